// L1: mean |x - target| over all pixels and channels (method.md 1.14).
#pragma once

#include <cmath>
#include <cstdint>

#include "mgsr/loss/loss_util.h"
#include "mgsr/loss/parallel_pixels.h"
#include "mgsr/loss/photometric_term.h"

namespace mgsr {

class L1Loss : public PhotometricTerm<L1Loss> {
 public:
  explicit L1Loss(Buffer buffer = Buffer::kColor, TargetKind target = TargetKind::kImage)
      : PhotometricTerm(buffer, target) {}
  std::string Name() const override { return Describe("l1"); }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& x = *in.Get(buffer_);
    const ImageT<T>& y = *SelectTarget(t, target_);
    const double inv_n = 1.0 / static_cast<double>(x.size());
    double sum = 0;
    T* g = grad ? grad->Get(buffer_, x).data() : nullptr;
    const T step = static_cast<T>(scale * inv_n);
    const T* xd = x.data();
    const T* yd = y.data();
    const size_t n = x.size();
    // The gradient element by element on all threads; the sum one simd reduction on one thread
    // (its order fixed by the build, not by the thread count).
    if (g != nullptr) {
      const int64_t count = static_cast<int64_t>(n);
#pragma omp parallel for simd schedule(static) if (count >= kParallelPixels)
      for (int64_t i = 0; i < count; ++i) {
        const T d = xd[i] - yd[i];
        g[i] += d > 0 ? step : (d < 0 ? -step : T(0));
      }
    }
#pragma omp simd reduction(+ : sum)
    for (size_t i = 0; i < n; ++i) sum += std::abs(xd[i] - yd[i]);
    return sum * inv_n;
  }
};

}  // namespace mgsr
