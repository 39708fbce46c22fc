// The paper's auto-stop (method.md 1.2): after a minimum iteration, keep the last `window` losses;
// stop when their range (max - min) falls below `range`.
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace mgsr {

class AutoStop {
 public:
  AutoStop(int min_iteration, int window, double range)
      : min_iteration_(min_iteration), window_(window), range_(range) {}
  // The recorded losses, oldest first (what a checkpoint keeps).
  std::vector<double> window() const {
    std::vector<double> w(losses_.begin() + head_, losses_.end());
    w.insert(w.end(), losses_.begin(), losses_.begin() + head_);
    return w;
  }
  void set_window(std::vector<double> w) {
    if (static_cast<int>(w.size()) > window_) w.erase(w.begin(), w.end() - window_);
    losses_ = std::move(w);
    head_ = 0;
  }

  // Records the loss of `iteration`; true once the window has flattened. A ring buffer of the
  // window's size: no allocation once it is full.
  bool Update(int iteration, double loss) {
    if (iteration <= min_iteration_) return false;
    if (static_cast<int>(losses_.size()) < window_) {
      losses_.push_back(loss);
    } else if (window_ > 0) {
      losses_[head_] = loss;  // the oldest
      head_ = (head_ + 1) % losses_.size();
    }
    if (static_cast<int>(losses_.size()) < window_ || losses_.empty()) return false;
    const auto [lo, hi] = std::minmax_element(losses_.begin(), losses_.end());
    return *hi - *lo < range_;
  }

 private:
  int min_iteration_, window_;
  double range_;
  std::vector<double> losses_;
  size_t head_ = 0;  // index of the oldest loss once the window is full
};

}  // namespace mgsr
