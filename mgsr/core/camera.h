// Camera: PINHOLE intrinsics and a world-to-camera pose in COLMAP conventions.
//   x_cam = R * X_world + t; camera axes x right, y down, z forward;
//   pixel (u, v) = (fx * x/z + cx, fy * y/z + cy), the top-left pixel's centre is at (0.5, 0.5).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace mgsr {

struct Camera {
  int width = 0;
  int height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world -> camera rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // world -> camera translation

  // Pose from a COLMAP quaternion (w, x, y, z), normalised here.
  void SetRotationFromQuaternion(double qw, double qx, double qy, double qz);
  // COLMAP quaternion (w, x, y, z) of R with w >= 0.
  Eigen::Vector4d RotationQuaternion() const;
  // Exactly the same intrinsics and pose.
  bool operator==(const Camera& o) const {
    return width == o.width && height == o.height && fx == o.fx && fy == o.fy && cx == o.cx &&
           cy == o.cy && R == o.R && t == o.t;
  }

  Eigen::Vector3d Center() const { return -R.transpose() * t; }
  Eigen::Vector3d WorldToCamera(const Eigen::Vector3d& X) const { return R * X + t; }
  Eigen::Vector3d CameraToWorld(const Eigen::Vector3d& Xc) const {
    return R.transpose() * (Xc - t);
  }
  // Pixel coordinates of a camera-space point (z must be > 0).
  Eigen::Vector2d CameraToPixel(const Eigen::Vector3d& Xc) const {
    return {fx * Xc.x() / Xc.z() + cx, fy * Xc.y() / Xc.z() + cy};
  }
  Eigen::Vector2d WorldToPixel(const Eigen::Vector3d& X) const {
    return CameraToPixel(WorldToCamera(X));
  }
  // Camera-space ray through pixel coordinates (u, v), with z = 1.
  Eigen::Vector3d PixelToRay(double u, double v) const {
    return {(u - cx) / fx, (v - cy) / fy, 1.0};
  }
  // 4x4 world-to-camera matrix.
  Eigen::Matrix4d WorldToCameraMatrix() const;

  double FovX() const;
  double FovY() const;

  // Same view at another resolution: intrinsics scaled so pixel footprints stay consistent
  // (the image plane [0, W] maps to [0, W'], so cx scales with the size, not with pixel centres).
  Camera Resized(int new_width, int new_height) const;

  // True when every number is finite and the intrinsics are positive.
  bool IsValid() const;
};

// A camera at `center` looking at `target` with the image's "up" as close to `up` as possible.
Camera LookAtCamera(const Eigen::Vector3d& center, const Eigen::Vector3d& target,
                    const Eigen::Vector3d& up, int width, int height, double fx, double fy);

}  // namespace mgsr
