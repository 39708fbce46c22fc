// Regression guard on where the reconstructed surface lies (issue #17): a short 2DGS run on a
// small synthetic scene, scored by mgsr_solve itself against the scene's exact mesh. The bounds
// catch a regression of the kind the exact metric was built to see (a convention slip of the pixel
// centre, the depth sign, the fusion's truncation; the reference's wide full-opacity screen
// low-pass again: mesh -1.26 to -1.35 px, median depth -1.60 px at this length; the reference's
// normal weight 0.05 again: mesh -0.98 px, expected depth -1.82 px), and the exact-depth ceiling
// must sit on the surface. 600 iterations are short of convergence (the mesh
// is deeper than after a full run); trajectories differ by about 0.1 px between builds.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "mgsr/io/file_util.h"
#include "tools/short_surfel_run.h"

namespace mgsr {
namespace {

TEST(SurfaceOffsetTest, ShortRunLiesWithinHalfAFootprintOfTheTruth) {
  const std::string dir = testing::ScratchDir();
  testing::CommandResult r;
  ASSERT_NO_FATAL_FAILURE(testing::ShortSurfelRun(
      dir, "--width 64 --height 64 --num_views 24 --seed 5 --mirror 0.3", &r));
  std::string text;
  ASSERT_TRUE(ReadFileToString(dir + "/out/metrics.json", &text).ok());
  const nlohmann::json m = nlohmann::json::parse(text);
  const double mesh_px = m["mesh"]["signed_offset_median_px"].get<double>();
  const double ceiling_px = m["mesh"]["ceiling"]["signed_offset_median_px"].get<double>();
  const double depth_px = m["depth"]["end"]["expected"]["median_px"].get<double>();
  // Measured (seed 5, the defaults: area-preserving low-pass of sigma 0.29 px, disks initialised
  // in the plane of their neighbours, normal weight 2.0): mesh -0.07 px, expected depth -0.39 px,
  // ceiling +0.07 px.
  EXPECT_GT(mesh_px, -0.45) << r.output;
  EXPECT_LT(mesh_px, 0.45) << r.output;
  EXPECT_GT(depth_px, -0.9) << r.output;
  EXPECT_LT(depth_px, 0.6) << r.output;
  EXPECT_LT(std::abs(ceiling_px), 0.25) << r.output;
}

// The silhouette term (MaskLoss, --lambda_mask) on a gear whose tooth gaps every view sees as
// background: without it the gaps web over (the photo loss cannot tell an empty pixel from a disk
// in the background's colour). Measured at 600 iterations, synth seeds 5 / 6 / 7: NC x100
// 77.7 / 77.0 / 77.7 without, 81.1 / 81.2 / 81.0 with weight 1; CD x1000 25.6 / 27.2 / 26.5
// against 21.6 / 21.8 / 22.1. One disk per initial point (--surfel_spread off): the wide first
// disks are what webs the gaps over; the spread's smaller ones (the default with masks) leave
// fewer webs for the term to empty in so short a run.
TEST(SurfaceOffsetTest, TheMaskTermEmptiesTheGapsBetweenAGearsTeeth) {
  const std::string dir = testing::ScratchDir();
  const std::string synth =
      "--width 64 --height 64 --num_views 24 --seed 5 --mirror 0.3 --shape gear";
  double nc[2], cd[2];
  for (int with = 0; with < 2; ++with) {
    testing::CommandResult r;
    const std::string out = with ? "mask" : "plain";
    ASSERT_NO_FATAL_FAILURE(
        testing::ShortSurfelRun(dir, synth, &r,
                                std::string(with ? "--lambda_mask 1" : "--lambda_mask 0") +
                                    " --normal_one_sided=false --surfel_spread off",
                                out));
    std::string text;
    ASSERT_TRUE(ReadFileToString(dir + "/" + out + "/metrics.json", &text).ok());
    const nlohmann::json m = nlohmann::json::parse(text);
    nc[with] = m["mesh"]["nc"].get<double>();
    cd[with] = m["mesh"]["cd"].get<double>();
  }
  EXPECT_GT(nc[1], nc[0] + 0.015);
  EXPECT_LT(cd[1], cd[0] * 0.92);
}

}  // namespace
}  // namespace mgsr
