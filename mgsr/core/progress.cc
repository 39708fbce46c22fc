#include "mgsr/core/progress.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace mgsr {
namespace {

std::string Seconds(double s) {
  char buf[32];
  if (s >= 120)
    std::snprintf(buf, sizeof(buf), "%.0f min", s / 60);
  else
    std::snprintf(buf, sizeof(buf), "%.0f s", s);
  return buf;
}

std::string Count(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), v == std::floor(v) ? "%.0f" : "%.1f", v);
  return buf;
}

}  // namespace

std::string ProgressLine(const std::string& label, const std::string& unit, double done,
                         double total, double elapsed_seconds) {
  total = std::max(total, 0.0);
  done = std::clamp(done, 0.0, total);
  const double pct = total > 0 ? 100.0 * done / total : 0.0;
  char buf[64];
  std::snprintf(buf, sizeof(buf), " (%.0f%%), ", pct);
  std::string line = label + ": " + Count(done) + "/" + Count(total) +
                     (unit.empty() ? "" : " " + unit) + buf + Seconds(elapsed_seconds);
  if (done > 0 && done < total)
    line += ", ~" + Seconds(elapsed_seconds / done * (total - done)) + " left";
  return line;
}

ProgressMeter::ProgressMeter(std::string label, std::string unit, double interval_seconds,
                             std::function<void(const std::string&)> sink)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      interval_(interval_seconds),
      sink_(std::move(sink)) {}

bool ProgressMeter::Update(double done, double total) {
  return UpdateAt(done, total, timer_.ElapsedSeconds());
}

bool ProgressMeter::UpdateAt(double done, double total, double elapsed_seconds) {
  if (!sink_ || done <= last_done_ || elapsed_seconds - last_print_ < interval_) return false;
  sink_(ProgressLine(label_, unit_, done, total, elapsed_seconds));
  last_print_ = elapsed_seconds;
  last_done_ = done;
  return true;
}

}  // namespace mgsr
