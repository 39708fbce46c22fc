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

// A photo-size run: the model grows 40-fold to its budget over the first ninth of the steps, and
// a step's cost grows only as the 0.3th power of the model (the per-pixel passes dominate). From
// the second progress line on, the estimate is within a factor of 1.5 of the truth (a line fitted
// through the windows and extrapolated to the budget was 2.6 and 2.0 times too long at the second
// and third lines).
TEST(EtaEstimatorTest, APhotoSizeRunWhoseCostBarelyGrowsIsNotOverpriced) {
  const int total = 4500, every = 100;
  const double budget = 430000;
  const auto primitives_at = [&](int step) {
    return std::min(budget, 10000 * std::pow(40.0, step / 500.0));
  };
  const auto cost = [](double n) { return 0.25 * std::pow(n / 10000, 0.3); };
  std::vector<double> truth_left(total + 1, 0.0);
  for (int s = total - 1; s >= 0; --s) truth_left[s] = truth_left[s + 1] + cost(primitives_at(s));
  EtaEstimator eta;
  double seconds = 0, window_seconds = 0, window_start_n = primitives_at(0);
  for (int s = 0; s < total; ++s) {
    seconds += cost(primitives_at(s));
    if ((s + 1) % every != 0) continue;
    const double n = primitives_at(s);
    eta.AddWindow(every, seconds - window_seconds, 0.5 * (n + window_start_n));
    window_seconds = seconds;
    window_start_n = n;
    if (s + 1 == every || s + 1 == total) continue;  // no growth to fit yet; nothing left
    const double left = eta.SecondsLeft(total - s - 1, budget);
    EXPECT_GT(left, truth_left[s + 1] / 1.5) << "step " << s;
    EXPECT_LT(left, 1.5 * truth_left[s + 1]) << "step " << s;
  }
}

TEST(EtaEstimatorTest, WithoutWindowsOrGrowthItIsTheMeasuredRate) {
  EtaEstimator eta;
  EXPECT_EQ(eta.SecondsLeft(100, 1000), 0);
  eta.AddWindow(100, 10, 5000);
  eta.AddWindow(100, 10, 5000);
  EXPECT_NEAR(eta.SecondsLeft(50, 5000), 5.0, 1e-12);
  // With no growth seen, a model heading for twice the size prices its steps at sqrt(2) times
  // (half-way, in logarithm, between a cost that does not grow and one proportional to the size).
  EXPECT_NEAR(eta.SecondsLeft(50, 10000), 5.0 * std::sqrt(2.0), 1e-9);
  eta.AddWindow(0, 10, 5000);  // ignored
  EXPECT_NEAR(eta.SecondsLeft(50, 5000), 5.0, 1e-12);
}

}  // namespace
}  // namespace mgsr
