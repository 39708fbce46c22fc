// Edge-aware total variation (reference 1.14, after GS-IR): for a buffer P (C x H x W) and a guide
// image I (3 channels),
//   TV = mean_{c,y<H-1,x} e^{-mean_ch |I(y+1,x) - I(y,x)|} (P(y+1,x) - P(y,x))^2
//      + mean_{c,y,x<W-1} e^{-mean_ch |I(y,x+1) - I(y,x)|} (P(y,x+1) - P(y,x))^2
// Applied to the transmitted colour, the depth and the normals; the guide is constant. The sums
// and their gradient are EdgeAwareTvSums' (mgsr/loss/edge_aware_tv_plane.h).
#pragma once

#include "mgsr/loss/edge_aware_tv_plane.h"
#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

class EdgeAwareTvLoss : public LossTermImpl<EdgeAwareTvLoss> {
 public:
  explicit EdgeAwareTvLoss(Buffer buffer = Buffer::kDepth, TargetKind guide = TargetKind::kImage)
      : buffer_(buffer), guide_(guide) {}
  std::string Name() const override {
    return std::string("tv(") + BufferName(buffer_) + ", " + TargetName(guide_) + ")";
  }
  std::vector<Buffer> Inputs() const override { return {buffer_}; }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), BufferName(buffer_), in.Get(buffer_)));
    return RequireImage(Name(), TargetName(guide_), SelectTarget(t, guide_), in.Get(buffer_), 3);
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& P = *in.Get(buffer_);
    const ImageT<T>& I = *SelectTarget(t, guide_);
    const int w = P.width(), h = P.height();
    if (w < 2 || h < 2) return 0.0;
    const double inv_v = 1.0 / (static_cast<double>(P.channels()) * (h - 1) * w);
    const double inv_h = 1.0 / (static_cast<double>(P.channels()) * h * (w - 1));
    double vertical = 0, horizontal = 0;
    EdgeAwareTvSums(P.data(), P.channels(), I.data(), I.channels(), w, h,
                    static_cast<T>(scale * inv_v), static_cast<T>(scale * inv_h),
                    grad ? grad->Get(buffer_, P).data() : nullptr, &vertical, &horizontal);
    return vertical * inv_v + horizontal * inv_h;
  }

 private:
  Buffer buffer_;
  TargetKind guide_;
};

}  // namespace mgsr
