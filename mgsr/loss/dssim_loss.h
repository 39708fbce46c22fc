// D-SSIM: 1 - SSIM, with SSIM as the reference computes it (reference 1.14): an 11x11 Gaussian
// window (sigma 1.5) per channel, zero padding, C1 = 0.01^2, C2 = 0.03^2, mean of the map. Means
// and second moments come from separable blurs; the backward uses that the zero-padded symmetric
// blur is its own adjoint: d/dx = G*(dS/dmu_x) + 2x G*(dS/dE[x^2]) + y G*(dS/dE[xy]).
#pragma once

#include <vector>

#include "mgsr/core/separable_blur.h"
#include "mgsr/loss/loss_util.h"
#include "mgsr/loss/photometric_term.h"

namespace mgsr {

class DssimLoss : public PhotometricTerm<DssimLoss> {
 public:
  explicit DssimLoss(Buffer buffer = Buffer::kColor, TargetKind target = TargetKind::kImage)
      : PhotometricTerm(buffer, target) {}
  std::string Name() const override { return Describe("dssim"); }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& x = *in.Get(buffer_);
    const ImageT<T>& y = *SelectTarget(t, target_);
    const int w = x.width(), h = x.height();
    const size_t n = x.plane_size();
    const T C1 = T(0.01 * 0.01), C2 = T(0.03 * 0.03);
    const std::vector<T> window = SsimWindowT<T>();
    std::vector<T> scratch, prod(n), mx(n), my(n), exx(n), eyy(n), exy(n), a1(n), a2(n), a3(n),
        b(n);
    double total = 0;
    const T dscale = static_cast<T>(-scale / static_cast<double>(x.size()));  // d(1 - mean S) / dS
    for (int c = 0; c < x.channels(); ++c) {
      const T* px = x.plane(c);
      const T* py = y.plane(c);
      BlurZeroPaddedT(px, w, h, window, mx.data(), &scratch);
      BlurZeroPaddedT(py, w, h, window, my.data(), &scratch);
      for (size_t i = 0; i < n; ++i) prod[i] = px[i] * px[i];
      BlurZeroPaddedT(prod.data(), w, h, window, exx.data(), &scratch);
      for (size_t i = 0; i < n; ++i) prod[i] = py[i] * py[i];
      BlurZeroPaddedT(prod.data(), w, h, window, eyy.data(), &scratch);
      for (size_t i = 0; i < n; ++i) prod[i] = px[i] * py[i];
      BlurZeroPaddedT(prod.data(), w, h, window, exy.data(), &scratch);
      for (size_t i = 0; i < n; ++i) {
        const T ux = mx[i], uy = my[i];
        const T vx = exx[i] - ux * ux, vy = eyy[i] - uy * uy, cxy = exy[i] - ux * uy;
        const T A = 2 * ux * uy + C1, B = 2 * cxy + C2, C = ux * ux + uy * uy + C1,
                D = vx + vy + C2;
        const T S = (A * B) / (C * D);
        total += S;
        if (grad) {
          // Partials of S in (mu_x, E[x^2], E[xy]), the others held fixed.
          a1[i] = dscale * (2 * uy * (B - A) / (C * D) - 2 * ux * S * (1 / C - 1 / D));
          a2[i] = dscale * (-S / D);
          a3[i] = dscale * (2 * A / (C * D));
        }
      }
      if (grad) {
        T* g = grad->Get(buffer_, x).plane(c);
        BlurZeroPaddedT(a1.data(), w, h, window, b.data(), &scratch);
        for (size_t i = 0; i < n; ++i) g[i] += b[i];
        BlurZeroPaddedT(a2.data(), w, h, window, b.data(), &scratch);
        for (size_t i = 0; i < n; ++i) g[i] += 2 * px[i] * b[i];
        BlurZeroPaddedT(a3.data(), w, h, window, b.data(), &scratch);
        for (size_t i = 0; i < n; ++i) g[i] += py[i] * b[i];
      }
    }
    return 1.0 - total / static_cast<double>(x.size());
  }
};

}  // namespace mgsr
