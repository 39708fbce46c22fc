// L1: mean |x - target| over all pixels and channels (reference 1.14).
#pragma once

#include <cmath>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

class L1Loss : public LossTermImpl<L1Loss> {
 public:
  explicit L1Loss(Buffer buffer = Buffer::kColor, TargetKind target = TargetKind::kImage)
      : buffer_(buffer), target_(target) {}
  std::string Name() const override {
    return std::string("l1(") + BufferName(buffer_) + ", " + TargetName(target_) + ")";
  }
  std::vector<Buffer> Inputs() const override { return {buffer_}; }
  std::vector<OtherBranchTarget> TargetInputs() const override {
    if (target_ == TargetKind::kTransmitted) return {OtherBranchTarget::kTransmitted};
    return {};
  }
  // Symmetric in the buffer and the target: the swapped gradient.
  template <typename T>
  void TargetGradient(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                      TargetGradientsT<T>* grad) const {
    if (target_ == TargetKind::kTransmitted)
      SwappedTransmittedGradient(*this, buffer_, in, t, scale, grad);
  }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), BufferName(buffer_), in.Get(buffer_)));
    return RequireImage(Name(), TargetName(target_), SelectTarget(t, target_), in.Get(buffer_),
                        in.Get(buffer_)->channels());
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& x = *in.Get(buffer_);
    const ImageT<T>& y = *SelectTarget(t, target_);
    const double inv_n = 1.0 / static_cast<double>(x.size());
    double sum = 0;
    T* g = grad ? grad->Get(buffer_, x).data() : nullptr;
    const T step = static_cast<T>(scale * inv_n);
    for (size_t i = 0; i < x.size(); ++i) {
      const T d = x.data()[i] - y.data()[i];
      sum += std::abs(d);
      if (g) g[i] += d > 0 ? step : (d < 0 ? -step : T(0));
    }
    return sum * inv_n;
  }

 private:
  Buffer buffer_;
  TargetKind target_;
};

}  // namespace mgsr
