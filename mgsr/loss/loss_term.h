// LossTerm: our ceres::CostFunction. A term declares the render buffers it reads, returns its
// value, and on request adds scale * d value / d buffer into the gradient buffers (targets are
// constants). Terms run in float during training and in double for gradient checks; a new term
// derives from LossTermImpl<Derived> and writes one templated Compute<T>(), which gives both.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "mgsr/core/status.h"
#include "mgsr/loss/render_buffers.h"

namespace mgsr {

class LossTerm {
 public:
  virtual ~LossTerm() = default;
  virtual std::string Name() const = 0;
  // Buffers the term differentiates.
  virtual std::vector<Buffer> Inputs() const = 0;
  // Buffers it reads as constants (stop-gradient), e.g. alpha in the normal consistency.
  virtual std::vector<Buffer> ConstantInputs() const { return {}; }
  // Checks that the inputs and targets the term needs are present and shaped alike.
  virtual Status Check(const RenderBuffers& in, const Targets& targets) const = 0;
  // Value; with grad != nullptr also adds scale * d value / d input buffer to grad.
  virtual double Evaluate(const RenderBuffers& in, const Targets& targets, double scale,
                          RenderGradients* grad) const = 0;
  virtual double Evaluate(const RenderBuffersD& in, const TargetsD& targets, double scale,
                          RenderGradientsD* grad) const = 0;
};

template <typename Derived>
class LossTermImpl : public LossTerm {
 public:
  double Evaluate(const RenderBuffers& in, const Targets& t, double scale,
                  RenderGradients* grad) const final {
    return static_cast<const Derived*>(this)->template Compute<float>(in, t, scale, grad);
  }
  double Evaluate(const RenderBuffersD& in, const TargetsD& t, double scale,
                  RenderGradientsD* grad) const final {
    return static_cast<const Derived*>(this)->template Compute<double>(in, t, scale, grad);
  }
};

}  // namespace mgsr
