#include "solvers/eta_estimator.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace mgsr {
namespace {

// A run whose model grows from 20k to its 120k budget over the first third of its steps (as
// MCMC's relocation grows it), each step costing 0.02 s + 2 us per primitive: the estimate, made
// as the progress lines make it, does not rise after the first few lines and ends within 15% of
// the truth at every line once the model has stopped growing.
TEST(EtaEstimatorTest, TheEstimateFallsWhileTheModelGrows) {
  const int total = 3000, every = 100;
  const double budget = 120000;
  const auto primitives_at = [&](int step) {
    return std::min(budget, 20000 * std::pow(1.06, step / 20.0));
  };
  const auto cost = [](double n) { return 0.02 + 2e-6 * n; };
  std::vector<double> truth_left(total + 1, 0.0);
  for (int s = total - 1; s >= 0; --s) truth_left[s] = truth_left[s + 1] + cost(primitives_at(s));
  EtaEstimator eta;
  double seconds = 0, window_seconds = 0, window_start_n = primitives_at(0);
  std::vector<double> estimates, plain;
  for (int s = 0; s < total; ++s) {
    seconds += cost(primitives_at(s));
    if ((s + 1) % every != 0) continue;
    const double n = primitives_at(s);
    eta.AddWindow(every, seconds - window_seconds, 0.5 * (n + window_start_n));
    const bool growing = n > window_start_n;
    window_seconds = seconds;
    window_start_n = n;
    const double left = eta.SecondsLeft(total - s - 1, growing ? budget : n);
    estimates.push_back(left);
    plain.push_back(seconds / (s + 1) * (total - s - 1));
    if (!growing && s > total / 2) {
      EXPECT_NEAR(left, truth_left[s + 1], 0.15 * truth_left[s + 1]) << "step " << s;
    }
  }
  int rises = 0;
  for (size_t k = 3; k < estimates.size(); ++k) rises += estimates[k] > estimates[k - 1] * 1.001;
  EXPECT_EQ(rises, 0) << ::testing::PrintToString(estimates);
  // The plain mean of the steps so far rises with the model for lines on end.
  int plain_rises = 0;
  for (size_t k = 3; k < plain.size(); ++k) plain_rises += plain[k] > plain[k - 1] * 1.001;
  EXPECT_GE(plain_rises, 5) << ::testing::PrintToString(plain);
}

TEST(EtaEstimatorTest, WithoutWindowsOrGrowthItIsTheMeasuredRate) {
  EtaEstimator eta;
  EXPECT_EQ(eta.SecondsLeft(100, 1000), 0);
  eta.AddWindow(100, 10, 5000);
  eta.AddWindow(100, 10, 5000);
  EXPECT_NEAR(eta.SecondsLeft(50, 5000), 5.0, 1e-12);
  // Proportional to the size it heads for when no slope can be fitted.
  EXPECT_NEAR(eta.SecondsLeft(50, 10000), 10.0, 1e-12);
  eta.AddWindow(0, 10, 5000);  // ignored
  EXPECT_NEAR(eta.SecondsLeft(50, 5000), 5.0, 1e-12);
}

}  // namespace
}  // namespace mgsr
