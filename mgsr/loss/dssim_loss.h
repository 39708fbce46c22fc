// D-SSIM: 1 - SSIM, with SSIM as the reference computes it (method.md 1.14): an 11x11 Gaussian
// window (sigma 1.5) per channel, zero padding, C1 = 0.01^2, C2 = 0.03^2, mean of the map. The
// per-plane map and its gradient are SsimPlaneSum's (mgsr/loss/dssim_plane.h).
#pragma once

#include "mgsr/loss/dssim_plane.h"
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
    const T dscale = static_cast<T>(-scale / static_cast<double>(x.size()));  // d(1 - mean S) / dS
    double total = 0;
    for (int c = 0; c < x.channels(); ++c) {
      total += SsimPlaneSum(x.plane(c), y.plane(c), x.width(), x.height(), dscale,
                            grad ? grad->Get(buffer_, x).plane(c) : nullptr);
    }
    return 1.0 - total / static_cast<double>(x.size());
  }
};

}  // namespace mgsr
