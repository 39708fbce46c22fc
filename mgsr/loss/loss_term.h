// LossTerm: our ceres::CostFunction. A term declares the render buffers it reads, returns its
// value, and on request adds scale * d value / d buffer into the gradient buffers. Targets are
// constants, except that a term comparing with the other branch's render may declare it
// (TargetInputs) and give its gradient with respect to it (bidirectional supervision). Terms run in
// float during training and in double for gradient checks; a new term derives from
// LossTermImpl<Derived> and writes one templated Compute<T>(), which gives both.
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
  // Multi-view terms: whether the term reads the neighbours' rendered depth (the trainer then
  // renders it for each neighbour of the view before the step). Neighbours' cameras and photos are
  // always in the targets when the scene has them.
  virtual bool ReadsNeighbourDepth() const { return false; }
  // Whether the term reads neighbouring views at all (their cameras and photos): the solver then
  // chooses each view's neighbours once and keeps every photo in grey.
  virtual bool ReadsNeighbours() const { return ReadsNeighbourDepth(); }
  // Checks that the inputs and targets the term needs are present and shaped alike.
  virtual Status Check(const RenderBuffers& in, const Targets& targets) const = 0;
  // Value; with grad != nullptr also adds scale * d value / d input buffer to grad.
  virtual double Evaluate(const RenderBuffers& in, const Targets& targets, double scale,
                          RenderGradients* grad) const = 0;
  virtual double Evaluate(const RenderBuffersD& in, const TargetsD& targets, double scale,
                          RenderGradientsD* grad) const = 0;
  // The other branch's renders among the targets that the term differentiates (bidirectional
  // supervision asks for scale * d value / d target of these; every other target is a constant).
  virtual std::vector<OtherBranchTarget> TargetInputs() const { return {}; }
  virtual void EvaluateTargetGradient(const RenderBuffers& in, const Targets& targets, double scale,
                                      TargetGradients* grad) const = 0;
  virtual void EvaluateTargetGradient(const RenderBuffersD& in, const TargetsD& targets,
                                      double scale, TargetGradientsD* grad) const = 0;
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
  void EvaluateTargetGradient(const RenderBuffers& in, const Targets& t, double scale,
                              TargetGradients* grad) const final {
    static_cast<const Derived*>(this)->template TargetGradient<float>(in, t, scale, grad);
  }
  void EvaluateTargetGradient(const RenderBuffersD& in, const TargetsD& t, double scale,
                              TargetGradientsD* grad) const final {
    static_cast<const Derived*>(this)->template TargetGradient<double>(in, t, scale, grad);
  }
  // A term with TargetInputs() writes its own; this default adds nothing.
  template <typename T>
  void TargetGradient(const RenderBuffersT<T>&, const TargetsT<T>&, double,
                      TargetGradientsT<T>*) const {}
};

// For a term symmetric in its input buffer and its target (L1, D-SSIM, their sum), comparing
// `buffer` with the transmitted target: d value / d target is the term's own gradient with the
// two swapped. Adds scale times it to grad->transmitted.
template <typename Term, typename T>
void SwappedTransmittedGradient(const Term& term, Buffer buffer, const RenderBuffersT<T>& in,
                                const TargetsT<T>& t, double scale, TargetGradientsT<T>* grad) {
  if (t.transmitted == nullptr || in.Get(buffer) == nullptr) return;
  RenderBuffersT<T> swapped = in;
  swapped.Set(buffer, t.transmitted);
  TargetsT<T> swapped_targets = t;
  swapped_targets.transmitted = in.Get(buffer);
  RenderGradientsT<T> g;
  term.template Compute<T>(swapped, swapped_targets, scale, &g);
  grad->Add(OtherBranchTarget::kTransmitted, std::move(g.images[static_cast<int>(buffer)]));
}

}  // namespace mgsr
