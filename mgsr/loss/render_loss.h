// The render loss of the paper: lambda L1 + (1 - lambda) D-SSIM, lambda = 0.8 (method.md 1.7,
// lambda_1).
#pragma once

#include "mgsr/loss/dssim_loss.h"
#include "mgsr/loss/l1_loss.h"

namespace mgsr {

class RenderLoss : public PhotometricTerm<RenderLoss> {
 public:
  explicit RenderLoss(Buffer buffer = Buffer::kColor, TargetKind target = TargetKind::kImage,
                      double lambda = 0.8)
      : PhotometricTerm(buffer, target),
        l1_(buffer, target),
        dssim_(buffer, target),
        lambda_(lambda) {}
  std::string Name() const override { return Describe("render"); }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    return l1_.Check(in, t);
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    return lambda_ * l1_.Compute(in, t, scale * lambda_, grad) +
           (1 - lambda_) * dssim_.Compute(in, t, scale * (1 - lambda_), grad);
  }

 private:
  L1Loss l1_;
  DssimLoss dssim_;
  double lambda_;
};

// The 2DGS branch's loss in the mutual stage (method.md 1.5, paper lambda_6): a render loss against
// the 3DGS branch's transmitted image (weight 0.2) plus one against the ground truth (weight 0.8).
class MutualRenderLoss : public LossTermImpl<MutualRenderLoss> {
 public:
  explicit MutualRenderLoss(double transmitted_weight = 0.2, double image_weight = 0.8,
                            double lambda = 0.8)
      : vs_transmitted_(Buffer::kColor, TargetKind::kTransmitted, lambda),
        vs_image_(Buffer::kColor, TargetKind::kImage, lambda),
        wt_(transmitted_weight),
        wi_(image_weight) {}
  std::string Name() const override { return "mutual_render"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kColor}; }
  std::vector<OtherBranchTarget> TargetInputs() const override {
    return {OtherBranchTarget::kTransmitted};
  }
  template <typename T>
  void TargetGradient(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                      TargetGradientsT<T>* grad) const {
    vs_transmitted_.TargetGradient(in, t, scale * wt_, grad);
  }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(vs_transmitted_.Check(in, t));
    return vs_image_.Check(in, t);
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    return wt_ * vs_transmitted_.Compute(in, t, scale * wt_, grad) +
           wi_ * vs_image_.Compute(in, t, scale * wi_, grad);
  }

 private:
  RenderLoss vs_transmitted_, vs_image_;
  double wt_, wi_;
};

}  // namespace mgsr
