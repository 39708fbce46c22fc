#include "solvers/eta_estimator.h"

#include <algorithm>
#include <cmath>

namespace mgsr {

void EtaEstimator::AddWindow(double steps, double seconds, double primitives) {
  if (!(steps > 0) || !(seconds >= 0) || !(primitives >= 0)) return;
  windows_.push_back({primitives, seconds / steps, steps});
  if (windows_.size() > kWindows) windows_.pop_front();
}

double EtaEstimator::SecondsPerStep(double primitives) const {
  if (windows_.empty()) return 0;
  // Weighted least squares (weights: steps) of seconds per step on primitives.
  double w = 0, mn = 0, mt = 0;
  for (const Window& x : windows_) {
    w += x.steps;
    mn += x.steps * x.primitives;
    mt += x.steps * x.seconds_per_step;
  }
  mn /= w;
  mt /= w;
  double snn = 0, snt = 0;
  for (const Window& x : windows_) {
    snn += x.steps * (x.primitives - mn) * (x.primitives - mn);
    snt += x.steps * (x.primitives - mn) * (x.seconds_per_step - mt);
  }
  const double spread = std::sqrt(snn / w);
  // The model barely changed over the windows: no slope to fit. Price it proportionally to its
  // size (an upper bound when it will grow: part of a step's cost does not grow with it).
  if (spread < 0.05 * mn || !(snn > 0)) return mn > 0 ? mt * primitives / mn : mt;
  double b = snt / snn;
  double a = mt - b * mn;
  if (b < 0) {  // cost falling as the model grows: noise; take the mean
    b = 0;
    a = mt;
  } else if (a < 0) {  // more than proportional: keep the line through the origin
    a = 0;
    b = mt / mn;
  }
  return a + b * primitives;
}

double EtaEstimator::SecondsLeft(double remaining_steps, double final_primitives) const {
  if (remaining_steps <= 0) return 0;
  return remaining_steps * SecondsPerStep(final_primitives);
}

}  // namespace mgsr
