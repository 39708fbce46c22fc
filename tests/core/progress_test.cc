#include "mgsr/core/progress.h"

#include <gtest/gtest.h>

#include <vector>

namespace mgsr {
namespace {

TEST(ProgressLine, CountsShareElapsedAndTimeLeft) {
  EXPECT_EQ(ProgressLine("meshing", "views", 12, 48, 3.0),
            "meshing: 12/48 views (25%), 3 s, ~9 s left");
  // Nothing done yet: no estimate; all done: none either.
  EXPECT_EQ(ProgressLine("mapping", "images", 0, 10, 4.0), "mapping: 0/10 images (0%), 4 s");
  EXPECT_EQ(ProgressLine("mapping", "images", 10, 10, 40.0), "mapping: 10/10 images (100%), 40 s");
  // Long times in minutes.
  EXPECT_EQ(ProgressLine("mgsr_bench", "runs", 6, 48, 600.0),
            "mgsr_bench: 6/48 runs (12%), 10 min, ~70 min left");
}

TEST(ProgressMeter, PrintsAtMostOnceAnIntervalAndOnlyWhenItMoved) {
  std::vector<std::string> lines;
  ProgressMeter meter("step", "images", 5.0, [&](const std::string& l) { lines.push_back(l); });
  EXPECT_FALSE(meter.UpdateAt(1, 10, 1.0));  // before the first interval
  EXPECT_TRUE(meter.UpdateAt(2, 10, 5.0));
  EXPECT_FALSE(meter.UpdateAt(3, 10, 9.0));   // too soon after the last line
  EXPECT_FALSE(meter.UpdateAt(2, 10, 11.0));  // no progress since
  EXPECT_TRUE(meter.UpdateAt(4, 10, 12.0));
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[1], "step: 4/10 images (40%), 12 s, ~18 s left");
  ProgressMeter silent("step", "images", 0.0, nullptr);
  EXPECT_FALSE(silent.UpdateAt(5, 10, 100.0));
}

}  // namespace
}  // namespace mgsr
