// The per-step rates the solver hands each branch: the position decay, and the surfels' shape
// decay that starts only once the 2DGS position rate has decayed.
#include "solvers/step_rates.h"

#include <gtest/gtest.h>

#include <cmath>

namespace mgsr {
namespace {

SolverOptions Options() {
  SolverOptions o;
  o.surfel_shape_decay = true;
  o.position_lr_max_steps = 1000;
  o.position_lr_max_steps_2d = 100;
  return o;
}

TEST(StepRatesTest, PositionDecaysLogLinearlyPerBranch) {
  const SolverOptions o = Options();
  const double extent = 2.0;
  EXPECT_DOUBLE_EQ(RatesAtStep(o, Branch::kSurfels2D, 0, extent).position,
                   extent * o.position_lr_init);
  EXPECT_NEAR(RatesAtStep(o, Branch::kSurfels2D, 50, extent).position,
              extent * std::sqrt(o.position_lr_init * o.position_lr_final), 1e-12);
  EXPECT_NEAR(RatesAtStep(o, Branch::kSurfels2D, 100, extent).position,
              extent * o.position_lr_final, 1e-12);
  EXPECT_NEAR(RatesAtStep(o, Branch::kSurfels2D, 5000, extent).position,
              extent * o.position_lr_final, 1e-12);
  // The 3DGS branch keeps its own, longer decay.
  EXPECT_NEAR(RatesAtStep(o, Branch::kGaussians3D, 500, extent).position,
              extent * std::sqrt(o.position_lr_init * o.position_lr_final), 1e-12);
}

TEST(StepRatesTest, SurfelShapeSettlesOnlyAfterThePositionHas) {
  const SolverOptions o = Options();
  const double fall = o.position_lr_final / o.position_lr_init;
  // Untouched through the position decay: a stage that ends by then (fast's) sees no change.
  for (int step : {0, 50, 100}) {
    const RateSchedule s = RatesAtStep(o, Branch::kSurfels2D, step, 1.0);
    EXPECT_DOUBLE_EQ(s.scale, o.scaling_lr) << step;
    EXPECT_DOUBLE_EQ(s.rotation, o.rotation_lr) << step;
  }
  // Then the same log-linear fall over as many steps again, and flat after it.
  const RateSchedule half = RatesAtStep(o, Branch::kSurfels2D, 150, 1.0);
  EXPECT_NEAR(half.scale, o.scaling_lr * std::sqrt(fall), 1e-12);
  EXPECT_NEAR(half.rotation, o.rotation_lr * std::sqrt(fall), 1e-12);
  for (int step : {200, 20000}) {
    const RateSchedule s = RatesAtStep(o, Branch::kSurfels2D, step, 1.0);
    EXPECT_NEAR(s.scale, o.scaling_lr * fall, 1e-15) << step;
    EXPECT_NEAR(s.rotation, o.rotation_lr * fall, 1e-15) << step;
    // Opacity and colour keep their rates: the appearance still fits.
    EXPECT_DOUBLE_EQ(s.opacity, o.opacity_lr);
    EXPECT_DOUBLE_EQ(s.color, o.feature_lr);
  }
  // Not the 3DGS branch, and not with the option off.
  const RateSchedule gaussians = RatesAtStep(o, Branch::kGaussians3D, 20000, 1.0);
  EXPECT_DOUBLE_EQ(gaussians.scale, o.scaling_lr);
  EXPECT_DOUBLE_EQ(gaussians.rotation, o.rotation_lr);
  SolverOptions off = o;
  off.surfel_shape_decay = false;
  const RateSchedule constant = RatesAtStep(off, Branch::kSurfels2D, 20000, 1.0);
  EXPECT_DOUBLE_EQ(constant.scale, o.scaling_lr);
  EXPECT_DOUBLE_EQ(constant.rotation, o.rotation_lr);
}

TEST(StepRatesTest, BatchesScaleEveryRateBySqrtOfTheBatch) {
  SolverOptions o = Options();
  o.batch_views = 4;
  o.batch_sqrt_lr = true;
  EXPECT_FLOAT_EQ(RatesAtStep(o, Branch::kSurfels2D, 0, 1.0).batch_factor, 2.0f);
  o.batch_sqrt_lr = false;
  EXPECT_FLOAT_EQ(RatesAtStep(o, Branch::kSurfels2D, 0, 1.0).batch_factor, 1.0f);
}

}  // namespace
}  // namespace mgsr
