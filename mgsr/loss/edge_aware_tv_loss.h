// Edge-aware total variation (method.md 1.14, after GS-IR): for a buffer P (C x H x W) and a guide
// image I (3 channels),
//   TV = mean_{c,y<H-1,x} e^{-mean_ch |I(y+1,x) - I(y,x)|} (P(y+1,x) - P(y,x))^2
//      + mean_{c,y,x<W-1} e^{-mean_ch |I(y,x+1) - I(y,x)|} (P(y,x+1) - P(y,x))^2
// Applied to the transmitted colour, the depth and the normals; the guide is constant. The sums
// and their gradient are EdgeAwareTvSums' (mgsr/loss/edge_aware_tv_plane.h).
// `on_geometry` weights each pair by the rendered alpha of both pixels (held constant): a depth
// TV then smooths the surfaces the branch has, not the step from a surface to the sky or the
// backdrop its pixels see through (an expected depth means nothing where alpha is ~0; pulling a
// horizon's or a silhouette's depth towards it bends the surface towards the camera).
// `disparity_scale` s > 0 (depth only) takes the TV of s^2 / D instead of D. The depth of a plane
// is convex along every image line (its inverse is affine), so a TV of D pulls every plane seen in
// perspective towards the camera, most where it recedes fast (a ground to the horizon); the TV of
// the disparity is zero on any plane and small where depth is large. At D = s the step is weighted
// as the reference's ((s^2/D)' = -1 there), so s = the object's distance keeps its weight on the
// object. Pixels with D <= 0 drop out.
#pragma once

#include <cmath>
#include <vector>

#include "mgsr/loss/edge_aware_tv_plane.h"
#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

class EdgeAwareTvLoss : public LossTermImpl<EdgeAwareTvLoss> {
 public:
  explicit EdgeAwareTvLoss(Buffer buffer = Buffer::kDepth, TargetKind guide = TargetKind::kImage,
                           bool on_geometry = false, double disparity_scale = 0)
      : buffer_(buffer),
        guide_(guide),
        on_geometry_(on_geometry),
        disparity_scale_(disparity_scale) {}
  std::string Name() const override {
    return std::string("tv(") + (disparity_scale_ > 0 ? "disparity of " : "") +
           BufferName(buffer_) + ", " + TargetName(guide_) +
           (on_geometry_ ? ", on geometry)" : ")");
  }
  std::vector<Buffer> Inputs() const override { return {buffer_}; }
  std::vector<Buffer> ConstantInputs() const override {
    if (on_geometry_) return {Buffer::kAlpha};
    return {};
  }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), BufferName(buffer_), in.Get(buffer_)));
    if (disparity_scale_ > 0 && buffer_ != Buffer::kDepth)
      return Status::Error(Name() + ": disparity_scale applies to the depth only");
    if (on_geometry_)
      MGSR_RETURN_IF_ERROR(
          RequireImage(Name(), "alpha", in.Get(Buffer::kAlpha), in.Get(buffer_), 1));
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
    const T* gamma = on_geometry_ ? in.Get(Buffer::kAlpha)->data() : nullptr;
    if (disparity_scale_ > 0) {
      // The kernel on Q = s^2 / D, and the chain rule dQ/dD = -Q / D. Pixels without depth get
      // weight 0 (no pair, no gradient).
      static thread_local std::vector<T> disparity, weight, q_grad;
      const size_t n = P.size();
      disparity.resize(n);
      weight.resize(n);
      const T s2 = static_cast<T>(disparity_scale_ * disparity_scale_);
      for (size_t i = 0; i < n; ++i) {
        const T d = P.data()[i];
        const bool defined = d > T(0) && std::isfinite(d);
        disparity[i] = defined ? s2 / d : T(0);
        weight[i] = defined ? (gamma ? gamma[i] : T(1)) : T(0);
      }
      if (grad) q_grad.assign(n, T(0));
      EdgeAwareTvSums(disparity.data(), 1, I.data(), I.channels(), weight.data(), w, h,
                      static_cast<T>(scale * inv_v), static_cast<T>(scale * inv_h),
                      grad ? q_grad.data() : nullptr, &vertical, &horizontal);
      if (grad) {
        T* g = grad->Get(buffer_, P).data();
        for (size_t i = 0; i < n; ++i) {
          if (weight[i] != T(0)) g[i] -= q_grad[i] * disparity[i] / P.data()[i];
        }
      }
      return vertical * inv_v + horizontal * inv_h;
    }
    EdgeAwareTvSums(P.data(), P.channels(), I.data(), I.channels(), gamma, w, h,
                    static_cast<T>(scale * inv_v), static_cast<T>(scale * inv_h),
                    grad ? grad->Get(buffer_, P).data() : nullptr, &vertical, &horizontal);
    return vertical * inv_v + horizontal * inv_h;
  }

 private:
  Buffer buffer_;
  TargetKind guide_;
  bool on_geometry_;
  double disparity_scale_;
};

}  // namespace mgsr
