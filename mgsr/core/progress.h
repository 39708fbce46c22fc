// Progress lines with an estimate of the time left, for the long stages that are not training
// (COLMAP's steps, meshing, the benchmark harness): "meshing: 12/48 views (25%), 3 s, ~9 s left".
// A meter prints at most one line per interval, so a fast stage stays quiet and a slow one still
// says where it is; the estimate assumes the remaining units cost what the done ones did.
#pragma once

#include <functional>
#include <string>
#include <utility>

#include "mgsr/core/timer.h"

namespace mgsr {

// "label: done/total unit (pct%), 12 s, ~36 s left"; the estimate is left out before any unit is
// done, and "~" times above two minutes read in minutes.
std::string ProgressLine(const std::string& label, const std::string& unit, double done,
                         double total, double elapsed_seconds);

class ProgressMeter {
 public:
  // `sink` receives each line (nullptr: silent); `interval` is the least time between lines.
  ProgressMeter(std::string label, std::string unit, double interval_seconds,
                std::function<void(const std::string&)> sink);
  // Reports `done` of `total` units at the meter's own clock; prints when the interval has passed
  // since the last line and the count moved. Returns whether it printed.
  bool Update(double done, double total);
  // The same at a given elapsed time (for tests and callers that keep their own clock).
  bool UpdateAt(double done, double total, double elapsed_seconds);
  void set_unit(std::string unit) { unit_ = std::move(unit); }

 private:
  std::string label_, unit_;
  double interval_;
  std::function<void(const std::string&)> sink_;
  Timer timer_;
  double last_print_ = 0, last_done_ = 0;
};

}  // namespace mgsr
