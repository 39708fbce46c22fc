// Regression guard on the 2DGS branch's single-iteration loss spikes (issue #18): with cameras far
// from the object every surfel is small and many are drawn by the screen low-pass, where a nearly
// edge-on disk once put the depth of its plane's far intersection (thousands of units) into a
// pixel's blend. Such a run logged losses up to 3.1e7 against a median of 3.8 (68 iterations above
// 5x the median in 600); with the centre's depth in that branch the largest is 1.7x the median.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tools/short_surfel_run.h"

namespace mgsr {
namespace {

TEST(LossSpikeTest, FarCamerasGiveNoSingleIterationSpikes) {
  const std::string dir = testing::ScratchDir();
  testing::CommandResult r;
  ASSERT_NO_FATAL_FAILURE(
      testing::ShortSurfelRun(dir, "--width 64 --height 64 --num_views 24 --distance 12", &r));
  // log.csv: stage,iteration,branch,loss,gaussians,surfels,seconds
  std::ifstream in(dir + "/out/log.csv");
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  std::vector<double> losses;
  while (std::getline(in, line)) {
    std::stringstream fields(line);
    std::string field;
    for (int column = 0; column < 4 && std::getline(fields, field, ','); ++column) {
    }
    losses.push_back(std::stod(field));
  }
  ASSERT_EQ(losses.size(), 600u);
  std::vector<double> sorted = losses;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];
  const double largest = *std::max_element(losses.begin(), losses.end());
  EXPECT_LT(largest, 3 * median) << "median " << median;
}

}  // namespace
}  // namespace mgsr
