// Pose comparison after a similarity alignment: exact on a transformed copy, the right angle and
// distance for a known perturbation, clear errors on degenerate input.
#include "mgsr/eval/pose_alignment.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "mgsr/core/rng.h"

namespace mgsr {
namespace {

std::vector<Camera> RingOfCameras(int n) {
  std::vector<Camera> cams;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    const Eigen::Vector3d eye(3 * std::cos(a), 3 * std::sin(a), 0.5 * std::sin(3 * a));
    cams.push_back(
        LookAtCamera(eye, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 64, 64, 50.0, 50.0));
  }
  return cams;
}

// The same rig in another frame: x' = s A x + b.
std::vector<Camera> Transformed(const std::vector<Camera>& cams, double s, const Eigen::Matrix3d& A,
                                const Eigen::Vector3d& b) {
  std::vector<Camera> out = cams;
  for (Camera& c : out) {
    const Eigen::Vector3d center = s * A * c.Center() + b;
    c.R = c.R * A.transpose();
    c.t = -c.R * center;
  }
  return out;
}

TEST(PoseAlignment, ASimilarityCopyHasNoError) {
  const auto truth = RingOfCameras(12);
  const Eigen::Matrix3d A =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const auto estimate = Transformed(truth, 0.37, A, Eigen::Vector3d(4, -1, 2));
  PoseErrors e;
  ASSERT_TRUE(ComparePoses(estimate, truth, &e).ok());
  EXPECT_EQ(e.num_poses, 12);
  EXPECT_NEAR(e.scale, 1 / 0.37, 1e-9);
  EXPECT_LT(e.max_rotation_deg, 1e-5);
  EXPECT_LT(e.max_translation_rel, 1e-9);
}

TEST(PoseAlignment, MeasuresAKnownRotationAndCentreError) {
  const auto truth = RingOfCameras(40);
  auto estimate = truth;
  // One camera turned by 2 degrees about its own centre, another moved: the alignment of 40
  // centres barely notices, so the errors come out as made.
  const Eigen::Vector3d c = estimate[5].Center();
  estimate[5].R = Eigen::AngleAxisd(2 * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                  estimate[5].R;
  estimate[5].t = -estimate[5].R * c;
  const Eigen::Vector3d moved = estimate[9].Center() + Eigen::Vector3d(0, 0, 0.03);
  estimate[9].t = -estimate[9].R * moved;
  PoseErrors e;
  ASSERT_TRUE(ComparePoses(estimate, truth, &e).ok());
  EXPECT_NEAR(e.max_rotation_deg, 2.0, 0.05);
  double extent = 0;
  for (const Camera& cam : truth) extent = std::max(extent, cam.Center().norm());
  // The alignment spreads a little of the move over all 40 centres.
  EXPECT_NEAR(e.max_translation_rel, 0.03 / extent, 0.1 * 0.03 / extent);
}

TEST(PoseAlignment, RejectsMismatchedAndDegenerateInput) {
  const auto truth = RingOfCameras(6);
  PoseErrors e;
  EXPECT_FALSE(ComparePoses({truth.begin(), truth.begin() + 5}, truth, &e).ok());
  EXPECT_FALSE(
      ComparePoses({truth.begin(), truth.begin() + 2}, {truth.begin(), truth.begin() + 2}, &e)
          .ok());
  std::vector<Camera> line = truth;
  for (size_t i = 0; i < line.size(); ++i) line[i].t = -line[i].R * Eigen::Vector3d(i, 0, 0);
  const Status s = ComparePoses(line, line, &e);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("collinear"), std::string::npos) << s.message();
  // Coincident centres are the line's limit; the truth may be a ring, only the estimate decides.
  std::vector<Camera> one_place = truth;
  for (Camera& c : one_place) c.t = -c.R * Eigen::Vector3d(1, 2, 3);
  EXPECT_NE(ComparePoses(one_place, truth, &e).message().find("collinear"), std::string::npos);
  // A line with one centre a millionth of its length off it still fixes the rotation.
  std::vector<Camera> near_line = line;
  near_line[2].t = -near_line[2].R * Eigen::Vector3d(2, 5e-6, 0);
  EXPECT_TRUE(ComparePoses(near_line, near_line, &e).ok());
}

}  // namespace
}  // namespace mgsr
