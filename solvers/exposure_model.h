// The per-view exposure parameter block: one affine colour transform per view (see
// mgsr/loss/exposure_compensation.h), learned with its own Adam step. A view's transform only moves
// when that view is trained, so each view keeps its own moments and step count (a sparse Adam, as
// for per-image appearance codes). A weak prior pulls every transform towards identity, which also
// fixes the global scale that the scene's colours and the gains could otherwise trade.
#pragma once

#include <vector>

#include "mgsr/loss/exposure_compensation.h"

namespace mgsr {

class ExposureModel {
 public:
  // `trained` lists the views whose transforms learn (the training views); the others stay at
  // identity.
  void Reset(int num_views, ExposureMode mode, const std::vector<int>& trained = {});
  ExposureMode mode() const { return mode_; }
  int num_views() const { return static_cast<int>(transforms_.size()); }
  bool enabled() const { return mode_ != ExposureMode::kOff; }

  const ColorTransform& transform(int view) const { return transforms_[view]; }
  // Replaces a view's transform (e.g. a closed-form fit) and restarts its moments.
  void SetTransform(int view, const ColorTransform& p);

  // One Adam step of the view's free parameters from d loss / d params, plus the priors
  // prior_weight * |A - I|^2 + offset_prior * |b|^2 on the view and, fixing the one free scale the
  // scene's colours and all transforms share (the gauge), mean_prior * N * |mean(p) - identity|^2
  // on the mean over the trained views: without it the transforms drift together and novel views,
  // rendered without a transform, come out at the wrong exposure.
  void Step(int view, const ColorTransform& gradient, double learning_rate, double prior_weight,
            double offset_prior, double mean_prior);

  // Flat state for checkpoints: per view 12 parameters, 12 + 12 moments, 1 step count.
  std::vector<double> SaveState() const;
  bool LoadState(const std::vector<double>& state, int num_views, ExposureMode mode,
                 const std::vector<int>& trained);

 private:
  ExposureMode mode_ = ExposureMode::kOff;
  std::vector<ColorTransform> transforms_, m_, v_;
  std::vector<int> steps_;
  std::vector<int> trained_;
};

}  // namespace mgsr
