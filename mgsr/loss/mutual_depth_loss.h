// Mutual depth loss of the 3DGS branch (method.md 1.5, 2.4; paper eq. 9): squared difference of the
// max-normalised depths of the two branches,
//   L_Z = mean gamma (D / max D - Z / max Z)^2,   Z = the 2DGS branch's depth (a constant target).
// The maxima are held constant (the reference's PyTorch code also sends a gradient to the argmax
// pixel; a constant max keeps the Jacobian clean and changes the step by one pixel's share).
// gamma is the mask when `masked` (the paper), 1 otherwise (the authors' code).
#pragma once

#include <algorithm>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

class MutualDepthLoss : public LossTermImpl<MutualDepthLoss> {
 public:
  explicit MutualDepthLoss(bool masked = false) : masked_(masked) {}
  std::string Name() const override { return masked_ ? "mutual_depth(masked)" : "mutual_depth"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kDepth}; }
  std::vector<OtherBranchTarget> TargetInputs() const override {
    return {OtherBranchTarget::kDepth};
  }
  // d L_Z / d Z = -2 gamma r / (n max Z), both maxima held constant.
  template <typename T>
  void TargetGradient(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                      TargetGradientsT<T>* grad) const {
    const ImageT<T>& D = *in.Get(Buffer::kDepth);
    const ImageT<T>& Z = *t.other_depth;
    T max_d = 0, max_z = 0;
    for (size_t i = 0; i < D.size(); ++i) {
      max_d = std::max(max_d, D.data()[i]);
      max_z = std::max(max_z, Z.data()[i]);
    }
    if (!(max_d > T(0)) || !(max_z > T(0))) return;
    ImageT<T> g(Z.width(), Z.height(), 1);
    const T c = static_cast<T>(2 * scale / static_cast<double>(D.size()));
    for (size_t i = 0; i < D.size(); ++i) {
      const T gamma = masked_ ? t.mask->data()[i] : T(1);
      const T r = D.data()[i] / max_d - Z.data()[i] / max_z;
      g.data()[i] = -c * gamma * r / max_z;
    }
    grad->Add(OtherBranchTarget::kDepth, std::move(g));
  }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), "depth", in.Get(Buffer::kDepth),
                                      static_cast<const Image*>(nullptr), 1));
    MGSR_RETURN_IF_ERROR(
        RequireImage(Name(), "the other branch's depth", t.other_depth, in.Get(Buffer::kDepth), 1));
    if (masked_) return RequireImage(Name(), "mask", t.mask, in.Get(Buffer::kDepth), 1);
    return Status::Ok();
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& D = *in.Get(Buffer::kDepth);
    const ImageT<T>& Z = *t.other_depth;
    T max_d = 0, max_z = 0;
    for (size_t i = 0; i < D.size(); ++i) {
      max_d = std::max(max_d, D.data()[i]);
      max_z = std::max(max_z, Z.data()[i]);
    }
    if (!(max_d > T(0)) || !(max_z > T(0))) return 0.0;
    const double inv_n = 1.0 / static_cast<double>(D.size());
    T* g = grad ? grad->Get(Buffer::kDepth, D).data() : nullptr;
    double total = 0;
    for (size_t i = 0; i < D.size(); ++i) {
      const T gamma = masked_ ? t.mask->data()[i] : T(1);
      const T r = D.data()[i] / max_d - Z.data()[i] / max_z;
      total += gamma * r * r;
      if (g) g[i] += static_cast<T>(2 * scale * inv_n) * gamma * r / max_d;
    }
    return total * inv_n;
  }

 private:
  bool masked_;
};

// Mean of the 2DGS depth-distortion buffer (method.md 3.4; unused by MGSR's defaults, weight 0).
class DistortionLoss : public LossTermImpl<DistortionLoss> {
 public:
  std::string Name() const override { return "distortion"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kDistortion}; }
  Status Check(const RenderBuffers& in, const Targets&) const override {
    return RequireImage(Name(), "distortion", in.Get(Buffer::kDistortion));
  }
  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>&, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& d = *in.Get(Buffer::kDistortion);
    const double inv_n = 1.0 / static_cast<double>(d.size());
    double total = 0;
    T* g = grad ? grad->Get(Buffer::kDistortion, d).data() : nullptr;
    for (size_t i = 0; i < d.size(); ++i) {
      total += d.data()[i];
      if (g) g[i] += static_cast<T>(scale * inv_n);
    }
    return total * inv_n;
  }
};

}  // namespace mgsr
