#include "solvers/step_rates.h"

#include <algorithm>
#include <cmath>

namespace mgsr {

double PositionLearningRate(const SolverOptions& o, Branch branch, int step, double extent) {
  const double t = std::clamp(static_cast<double>(step) / o.PositionDecaySteps(branch), 0.0, 1.0);
  return extent *
         std::exp(std::log(o.position_lr_init) * (1 - t) + std::log(o.position_lr_final) * t);
}

double SurfelShapeRateFactor(const SolverOptions& o, int step) {
  const double d = o.PositionDecaySteps(Branch::kSurfels2D);
  const double t = std::clamp((step - d) / d, 0.0, 1.0);
  return std::exp(std::log(o.position_lr_final / o.position_lr_init) * t);
}

// With the sqrt(batch) rule (SolverOptions::batch_sqrt_lr).
RateSchedule RatesAtStep(const SolverOptions& o, Branch branch, int step, double extent) {
  RateSchedule s;
  s.position = PositionLearningRate(o, branch, step, extent);
  s.scale = o.scaling_lr;
  s.rotation = o.rotation_lr;
  if (branch == Branch::kSurfels2D && o.surfel_shape_decay) {
    const double f = SurfelShapeRateFactor(o, step);
    s.scale *= f;
    s.rotation *= f;
  }
  s.opacity = o.opacity_lr;
  s.color = o.feature_lr;
  s.reflection = o.reflection;
  if (o.batch_views > 1 && o.batch_sqrt_lr)
    s.batch_factor = static_cast<float>(std::sqrt(static_cast<double>(o.batch_views)));
  return s;
}

}  // namespace mgsr
