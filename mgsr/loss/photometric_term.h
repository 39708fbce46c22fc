// What the photometric terms (L1, D-SSIM, the render loss) share: one buffer compared with a target
// image, the photo or the other branch's transmitted colour. They are symmetric in the two, so the
// gradient with respect to a transmitted target is the term's own with the two swapped
// (SwappedTransmittedGradient); that target is declared for bidirectional supervision.
#pragma once

#include <string>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

template <typename Derived>
class PhotometricTerm : public LossTermImpl<Derived> {
 public:
  PhotometricTerm(Buffer buffer, TargetKind target) : buffer_(buffer), target_(target) {}

  std::vector<Buffer> Inputs() const override { return {buffer_}; }
  std::vector<OtherBranchTarget> TargetInputs() const override {
    if (target_ == TargetKind::kTransmitted) return {OtherBranchTarget::kTransmitted};
    return {};
  }
  template <typename T>
  void TargetGradient(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                      TargetGradientsT<T>* grad) const {
    if (target_ == TargetKind::kTransmitted)
      SwappedTransmittedGradient(static_cast<const Derived&>(*this), buffer_, in, t, scale, grad);
  }
  // The buffer and a target of its shape exist.
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    const std::string name = this->Name();
    MGSR_RETURN_IF_ERROR(RequireImage(name, BufferName(buffer_), in.Get(buffer_)));
    return RequireImage(name, TargetName(target_), SelectTarget(t, target_), in.Get(buffer_),
                        in.Get(buffer_)->channels());
  }

 protected:
  // "kind(buffer, target)": the term's name.
  std::string Describe(const char* kind) const {
    return std::string(kind) + "(" + BufferName(buffer_) + ", " + TargetName(target_) + ")";
  }

  Buffer buffer_;
  TargetKind target_;
};

}  // namespace mgsr
