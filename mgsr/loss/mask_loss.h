// Silhouette loss: the branch's accumulated opacity against the view's foreground mask, as binary
// cross-entropy,
//   L = mean -(m log a + (1 - m) log(1 - a)),   a = alpha clamped to [eps, 1 - eps],
// d L / d a = (a - m) / (a (1 - a)) / n inside the clamp and 0 outside it.
// The photometric terms cannot tell an empty pixel from a surface painted in the background's
// colour, so without it a hole or a gap that every view sees as background can fill with disks
// that the smoothness prior pulls across it (the torus's hole, the gaps between a gear's teeth).
// The mask is what all views agree on about where the object is not. Without a mask the term is
// 0: it only adds what the capture knows. With `foreground` false only the background half
// remains (-log(1 - a) where the mask is empty: space carving; the rim is left to the photo).
#pragma once

#include <algorithm>
#include <cmath>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

class MaskLoss : public LossTermImpl<MaskLoss> {
 public:
  // Keeps log() finite and the gradient bounded (1 / eps) where a pixel is fully opaque or empty.
  static constexpr double kEps = 1e-3;

  explicit MaskLoss(bool foreground = true) : foreground_(foreground) {}
  std::string Name() const override { return foreground_ ? "mask" : "mask(background)"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kAlpha}; }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), "alpha", in.Get(Buffer::kAlpha),
                                      static_cast<const Image*>(nullptr), 1));
    if (t.mask == nullptr) return Status::Ok();
    return RequireImage(Name(), "mask", t.mask, in.Get(Buffer::kAlpha), 1);
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    if (t.mask == nullptr) return 0.0;
    const ImageT<T>& A = *in.Get(Buffer::kAlpha);
    const T* m = t.mask->data();
    const double inv_n = 1.0 / static_cast<double>(A.size());
    T* g = grad ? grad->Get(Buffer::kAlpha, A).data() : nullptr;
    // Most pixels sit at the clamp (the empty background, the opaque inside), where both
    // logarithms are constants; and a binary mask needs only one of them. Same values, bit for bit.
    // log(hi) is log(1 - lo); log(1 - hi) differs from log(lo) in its last bits (1 - (1 - lo)).
    const double lo = kEps, hi = 1.0 - kEps;
    const double log_lo = std::log(lo), log_hi = std::log(hi), log_1m_hi = std::log(1.0 - hi);
    double total = 0;
    for (size_t i = 0; i < A.size(); ++i) {
      const double raw = static_cast<double>(A.data()[i]);
      double mi = std::clamp(static_cast<double>(m[i]), 0.0, 1.0);
      if (!foreground_) {
        if (mi >= 0.5) continue;
        mi = 0;
      }
      double log_a, log_1m_a;
      if (raw <= lo) {
        log_a = log_lo;
        log_1m_a = log_hi;
      } else if (raw >= hi) {
        log_a = log_hi;
        log_1m_a = log_1m_hi;
      } else {
        log_a = mi > 0 ? std::log(raw) : 0.0;
        log_1m_a = mi < 1 ? std::log(1.0 - raw) : 0.0;
        if (g) g[i] += static_cast<T>(scale * inv_n * (raw - mi) / (raw * (1.0 - raw)));
      }
      total -= mi * log_a + (1.0 - mi) * log_1m_a;
    }
    return total * inv_n;
  }

 private:
  bool foreground_;
};

}  // namespace mgsr
