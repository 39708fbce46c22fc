// Wall-clock timer and process memory figures used in logs and metrics.json.
#pragma once

#include <chrono>
#include <cstdint>

namespace mgsr {

class Timer {
 public:
  Timer() { Restart(); }
  void Restart() { start_ = std::chrono::steady_clock::now(); }
  double ElapsedSeconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

// Peak resident set size of this process in bytes (getrusage), 0 when unavailable.
int64_t PeakMemoryBytes();

}  // namespace mgsr
