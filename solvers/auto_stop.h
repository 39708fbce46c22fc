// The paper's auto-stop (reference 1.2): after a minimum iteration, keep the last `window` losses;
// stop when their range (max - min) falls below `range`.
#pragma once

#include <algorithm>
#include <deque>
#include <utility>

namespace mgsr {

class AutoStop {
 public:
  AutoStop(int min_iteration, int window, double range)
      : min_iteration_(min_iteration), window_(window), range_(range) {}
  // Records the loss of `iteration`; true once the window has flattened.
  const std::deque<double>& window() const { return losses_; }
  void set_window(std::deque<double> w) { losses_ = std::move(w); }

  bool Update(int iteration, double loss) {
    if (iteration <= min_iteration_) return false;
    losses_.push_back(loss);
    if (static_cast<int>(losses_.size()) > window_) losses_.pop_front();
    if (static_cast<int>(losses_.size()) < window_) return false;
    const auto [lo, hi] = std::minmax_element(losses_.begin(), losses_.end());
    return *hi - *lo < range_;
  }

 private:
  int min_iteration_, window_;
  double range_;
  std::deque<double> losses_;
};

}  // namespace mgsr
