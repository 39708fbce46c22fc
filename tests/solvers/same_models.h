// Two solvers' trained state, compared bit for bit: both models' blocks, the learnt backgrounds
// and the per-view colour transforms.
#pragma once

#include <gtest/gtest.h>

#include "solvers/mutual_boosted_solver.h"

namespace mgsr {
namespace testing {

inline void ExpectSameModels(const MutualBoostedSolver& a, const MutualBoostedSolver& b) {
  GaussianModel ga = a.gaussians(), gb = b.gaussians();
  SurfelModel sa = a.surfels(), sb = b.surfels();
  ASSERT_EQ(ga.size(), gb.size());
  ASSERT_EQ(sa.size(), sb.size());
  const auto ba = ga.Blocks(), bb = gb.Blocks();
  for (size_t k = 0; k < ba.size(); ++k) EXPECT_EQ(*ba[k].data, *bb[k].data) << ba[k].name;
  const auto ca = sa.Blocks(), cb = sb.Blocks();
  for (size_t k = 0; k < ca.size(); ++k) EXPECT_EQ(*ca[k].data, *cb[k].data) << ca[k].name;
  for (Branch branch : {Branch::kSurfels2D, Branch::kGaussians3D}) {
    ASSERT_EQ(a.environment(branch) == nullptr, b.environment(branch) == nullptr);
    if (a.environment(branch) != nullptr) {
      EXPECT_EQ(a.environment(branch)->map().texels, b.environment(branch)->map().texels);
    }
    const ExposureModel &ea = a.exposure(branch), &eb = b.exposure(branch);
    ASSERT_EQ(ea.num_views(), eb.num_views());
    for (int v = 0; v < ea.num_views(); ++v)
      EXPECT_EQ(ea.transform(v), eb.transform(v)) << BranchLabel(branch) << " view " << v;
  }
}

}  // namespace testing
}  // namespace mgsr
