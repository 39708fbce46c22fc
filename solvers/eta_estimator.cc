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
  // Weighted least squares (weights: steps) of log(seconds per step) on log(primitives): a step's
  // cost as c * primitives^k. How fast it grows depends on the scene: the smaller the images, the
  // more the per-primitive passes weigh; at photo size the per-pixel ones do (a 1440 px render of
  // 250k primitives costs 1.5 times one of 15k: k near 0.15), and while a model first covers a
  // scene the cost rises faster than it will later. A line through the windows, extrapolated to
  // the budget, had priced a 1600 px capture at 8 times what was left at its first progress line
  // and nearly twice at the next two.
  double w = 0, ln = 0, lt = 0, mt = 0, steps = 0;
  for (const Window& x : windows_) {
    steps += x.steps;
    mt += x.steps * x.seconds_per_step;
    if (!(x.primitives > 0) || !(x.seconds_per_step > 0)) continue;
    w += x.steps;
    ln += x.steps * std::log(x.primitives);
    lt += x.steps * std::log(x.seconds_per_step);
  }
  if (!(w > 0) || !(primitives > 0)) return mt / steps;  // no sizes: the mean rate
  ln /= w;
  lt /= w;
  double snn = 0, snt = 0;
  for (const Window& x : windows_) {
    if (!(x.primitives > 0) || !(x.seconds_per_step > 0)) continue;
    const double dn = std::log(x.primitives) - ln;
    snn += x.steps * dn * dn;
    snt += x.steps * dn * (std::log(x.seconds_per_step) - lt);
  }
  // The model barely changed over the windows (under 5% spread): no exponent to fit; take 1/2,
  // between a cost that does not grow with the model and one proportional to it.
  const double k = snn > 0.05 * 0.05 * w ? std::clamp(snt / snn, 0.0, 1.0) : 0.5;
  return std::exp(lt + k * (std::log(primitives) - ln));
}

double EtaEstimator::SecondsLeft(double remaining_steps, double final_primitives) const {
  if (remaining_steps <= 0) return 0;
  return remaining_steps * SecondsPerStep(final_primitives);
}

}  // namespace mgsr
