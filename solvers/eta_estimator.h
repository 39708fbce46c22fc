// The time a training run has left, for its progress lines. A step's cost grows with the model
// (projection, binning and blending scale with the primitives, and more of them cover more of
// the views), and the model grows while the density strategy adds primitives: the seconds per
// step measured so far understate what the rest costs. The estimator fits seconds per step =
// c * primitives^k over the latest progress windows and prices the remaining steps at the size
// the model is heading for (its budget while it still grows, its present size once it stops), so
// the estimate falls as the run goes instead of climbing with the model.
#pragma once

#include <cstddef>
#include <deque>

namespace mgsr {

class EtaEstimator {
 public:
  // One progress window: `steps` steps took `seconds` at a model of `primitives` (its mean over
  // the window).
  void AddWindow(double steps, double seconds, double primitives);
  // Seconds left for `remaining_steps`, the model heading for `final_primitives`. Falls back on
  // the plain mean when no window is known.
  double SecondsLeft(double remaining_steps, double final_primitives) const;
  // c * primitives^k as fitted (seconds per step).
  double SecondsPerStep(double primitives) const;
  bool has_windows() const { return !windows_.empty(); }

 private:
  struct Window {
    double primitives, seconds_per_step, steps;
  };
  std::deque<Window> windows_;  // the latest kWindows
  static constexpr size_t kWindows = 8;
};

}  // namespace mgsr
