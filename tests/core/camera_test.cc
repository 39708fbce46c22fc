#include "mgsr/core/camera.h"

#include <gtest/gtest.h>

#include <cmath>

namespace mgsr {
namespace {

TEST(CameraTest, QuaternionRoundTrip) {
  Camera c;
  const Eigen::Vector4d q = Eigen::Vector4d(0.3, -0.5, 0.7, 0.2).normalized();
  c.SetRotationFromQuaternion(q[0], q[1], q[2], q[3]);
  EXPECT_NEAR((c.R * c.R.transpose() - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
  EXPECT_NEAR((c.RotationQuaternion() - q).norm(), 0, 1e-12);
}

TEST(CameraTest, ColmapPixelConventions) {
  Camera c;
  c.width = 100;
  c.height = 80;
  c.fx = 120;
  c.fy = 110;
  c.cx = 50;
  c.cy = 40;
  c.SetRotationFromQuaternion(0.9, 0.1, -0.2, 0.3);
  c.t = {0.1, -0.2, 3.0};
  const Eigen::Vector3d X(0.2, 0.3, -0.1);
  const Eigen::Vector2d uv = c.WorldToPixel(X);
  const Eigen::Vector3d Xc = c.WorldToCamera(X);
  // Back-project the pixel at the point's depth.
  const Eigen::Vector3d back = c.CameraToWorld(c.PixelToRay(uv.x(), uv.y()) * Xc.z());
  EXPECT_NEAR((back - X).norm(), 0, 1e-12);
  // The optical axis hits the principal point; x right, y down.
  EXPECT_NEAR((c.CameraToPixel({0, 0, 2}) - Eigen::Vector2d(50, 40)).norm(), 0, 1e-12);
  EXPECT_GT(c.CameraToPixel({0.1, 0, 1}).x(), 50);
  EXPECT_GT(c.CameraToPixel({0, 0.1, 1}).y(), 40);
  EXPECT_NEAR((c.Center() - c.CameraToWorld(Eigen::Vector3d::Zero())).norm(), 0, 1e-12);
}

TEST(CameraTest, LookAtPutsTargetAtCentreWithZUp) {
  const Camera c = LookAtCamera({3, 1, 2}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64, 48, 50, 50);
  EXPECT_TRUE(c.IsValid());
  EXPECT_NEAR((c.WorldToPixel(Eigen::Vector3d::Zero()) - Eigen::Vector2d(32, 24)).norm(), 0, 1e-9);
  // A point above the target appears higher in the image (smaller v).
  EXPECT_LT(c.WorldToPixel({0, 0, 0.5}).y(), 24);
  EXPECT_NEAR((c.Center() - Eigen::Vector3d(3, 1, 2)).norm(), 0, 1e-12);
}

TEST(CameraTest, ResizedKeepsImagePlaneFootprint) {
  Camera c = LookAtCamera({0, -3, 0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64, 64, 80, 80);
  const Camera half = c.Resized(32, 32);
  const Eigen::Vector3d X(0.3, 0.2, 0.1);
  EXPECT_NEAR((half.WorldToPixel(X) - 0.5 * c.WorldToPixel(X)).norm(), 0, 1e-12);
  EXPECT_NEAR(half.FovX(), c.FovX(), 1e-12);
}

TEST(CameraTest, InvalidCamerasAreDetected) {
  Camera c = LookAtCamera({0, -3, 0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64, 64, 80, 80);
  EXPECT_TRUE(c.IsValid());
  Camera nan = c;
  nan.t.x() = std::nan("");
  EXPECT_FALSE(nan.IsValid());
  Camera zero = c;
  zero.fx = 0;
  EXPECT_FALSE(zero.IsValid());
}

}  // namespace
}  // namespace mgsr

#include "mgsr/core/image.h"

namespace mgsr {
namespace {

TEST(ImageTest, MovedFromImageIsEmpty) {
  Image a(4, 3, 2, 1.0f);
  Image b = std::move(a);
  EXPECT_EQ(b.width(), 4);
  EXPECT_EQ(b.size(), 24u);
  EXPECT_TRUE(a.empty());
  EXPECT_EQ(a.width(), 0);  // a shape without data would invite writes past the end
  Image c;
  c = std::move(b);
  EXPECT_EQ(c.channels(), 2);
  EXPECT_EQ(b.channels(), 0);
}

}  // namespace
}  // namespace mgsr
