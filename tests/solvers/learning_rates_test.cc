// Each primitive type's learning-rate table: every block of its model has a rate, the kinds map
// onto the schedule, and a block no table lists stops the program instead of training at rate 0.
#include "solvers/learning_rates.h"

#include <gtest/gtest.h>

#include "mgsr/model/gaussian_model.h"
#include "mgsr/model/surfel_model.h"
#include "solvers/primitive_types.h"

namespace mgsr {
namespace {

RateSchedule Schedule() {
  RateSchedule s;
  s.position = 1e-4;
  s.scale = 5e-3;
  s.rotation = 1e-3;
  s.opacity = 0.05;
  s.color = 2.5e-3;
  return s;
}

TEST(LearningRatesTest, EveryBlockOfBothModelsHasItsRate) {
  std::vector<float> r;
  GaussianModel g;
  g.Resize(2);
  for (const ParamBlock& b : g.Blocks()) {
    r.assign(b.width, -1.0f);
    GaussianPrimitive::LearningRates(Schedule(), b.name, b.width, &r);
    for (float x : r) EXPECT_GT(x, 0.0f) << b.name;
  }
  SurfelModel s;
  s.Resize(2);
  for (const ParamBlock& b : s.Blocks()) {
    r.assign(b.width, -1.0f);
    SurfelPrimitive::LearningRates(Schedule(), b.name, b.width, &r);
    for (float x : r) EXPECT_GT(x, 0.0f) << b.name;
  }
  // SH: band 0 at the colour rate, the rest at a twentieth; the reflected layer freezes without
  // reflection; the batch factor scales everything.
  RateSchedule sched = Schedule();
  r.assign(48, 0.0f);
  GaussianPrimitive::LearningRates(sched, "sh", 48, &r);
  EXPECT_FLOAT_EQ(r[2], 2.5e-3f);
  EXPECT_FLOAT_EQ(r[3], static_cast<float>(2.5e-3 / 20));
  sched.reflection = false;
  GaussianPrimitive::LearningRates(sched, "ref_sh", 48, &r);
  EXPECT_EQ(r[0], 0.0f);
  r.assign(1, 0.0f);
  GaussianPrimitive::LearningRates(sched, "beta_logits", 1, &r);
  EXPECT_EQ(r[0], 0.0f);
  sched.batch_factor = 2.0f;
  GaussianPrimitive::LearningRates(sched, "opacity_logits", 1, &r);
  EXPECT_FLOAT_EQ(r[0], 0.1f);
}

TEST(LearningRatesDeathTest, ABlockNoTableListsStopsTheProgram) {
  std::vector<float> r(3);
  EXPECT_DEATH(SurfelPrimitive::LearningRates(Schedule(), "ref_sh", 3, &r),
               "the surfel primitive has no learning rate for parameter block 'ref_sh'");
}

}  // namespace
}  // namespace mgsr
