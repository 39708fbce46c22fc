#include "mgsr/eval/depth_error.h"

#include <gtest/gtest.h>

#include <cmath>

namespace mgsr {
namespace {

// A 4x2 camera at the origin with focal length 100: at depth 2 one pixel covers 0.02 units.
Camera TestCamera() {
  return LookAtCamera(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0, -1, 0),
                      4, 2, 100, 100);
}

TEST(DepthErrorTest, StatisticsAreSignedAndInFootprints) {
  const Camera cam = TestCamera();
  Image truth(4, 2, 1, 2.0f), rendered(4, 2, 1, 2.0f), mask(4, 2, 1, 1.0f);
  rendered.at(0, 0, 0) = 2.03f;  // 1.5 footprints behind the true surface (inside)
  rendered.at(0, 0, 1) = 2.01f;  // 0.5 behind
  rendered.at(0, 0, 2) = 1.99f;  // 0.5 in front
  rendered.at(0, 0, 3) = 2.01f;
  rendered.at(0, 1, 0) = 2.01f;
  rendered.at(0, 1, 1) = 2.01f;
  truth.at(0, 1, 2) = 0;    // no true surface: not counted
  mask.at(0, 1, 3) = 0.2f;  // outside the mask: not counted
  DepthErrorAccumulator acc;
  acc.Add(rendered, truth, &mask, cam);
  const DepthErrorStats s = acc.Finish();
  EXPECT_EQ(s.pixels, 6u);
  EXPECT_NEAR(s.median, -0.01, 1e-6);
  EXPECT_NEAR(s.median_footprints, -0.5, 1e-4);
  EXPECT_NEAR(s.share_beyond_footprint, 1.0 / 6, 1e-9);
  EXPECT_NEAR(s.mean, (-0.03 - 0.01 + 0.01 - 0.01 * 3) / 6, 1e-6);

  // The picture: red in front, blue behind, white on the surface, black where nothing counts.
  const Image e = SignedDepthErrorImage(rendered, truth, &mask, cam, 1.0);
  ASSERT_EQ(e.channels(), 3);
  auto rgb = [&](int y, int x) {
    return Eigen::Vector3f(e.at(0, y, x), e.at(1, y, x), e.at(2, y, x));
  };
  EXPECT_TRUE(rgb(0, 0).isApprox(Eigen::Vector3f(0, 0, 1)));  // saturated: 1.5 > 1 footprint
  EXPECT_TRUE(rgb(0, 1).isApprox(Eigen::Vector3f(0.5f, 0.5f, 1), 1e-3f));
  EXPECT_TRUE(rgb(0, 2).isApprox(Eigen::Vector3f(1, 0.5f, 0.5f), 1e-3f));
  EXPECT_EQ(rgb(1, 2), Eigen::Vector3f::Zero());
  EXPECT_EQ(rgb(1, 3), Eigen::Vector3f::Zero());
  rendered.at(0, 0, 0) = 2.0f;
  const Image exact = SignedDepthErrorImage(rendered, truth, nullptr, cam, 1.0);
  EXPECT_EQ(exact.at(0, 0, 0), 1.0f);
  EXPECT_EQ(exact.at(1, 0, 0), 1.0f);
  EXPECT_EQ(exact.at(2, 0, 0), 1.0f);
}

}  // namespace
}  // namespace mgsr
