#include "mgsr/core/camera.h"

#include <cmath>

namespace mgsr {

void Camera::SetRotationFromQuaternion(double qw, double qx, double qy, double qz) {
  R = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
}

Eigen::Vector4d Camera::RotationQuaternion() const {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;
  return {q.w(), q.x(), q.y(), q.z()};
}

Eigen::Matrix4d Camera::WorldToCameraMatrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = R;
  m.topRightCorner<3, 1>() = t;
  return m;
}

double Camera::FovX() const { return 2.0 * std::atan(width / (2.0 * fx)); }
double Camera::FovY() const { return 2.0 * std::atan(height / (2.0 * fy)); }

Camera Camera::Resized(int new_width, int new_height) const {
  Camera c = *this;
  const double sx = static_cast<double>(new_width) / width;
  const double sy = static_cast<double>(new_height) / height;
  c.width = new_width;
  c.height = new_height;
  c.fx *= sx;
  c.cx *= sx;
  c.fy *= sy;
  c.cy *= sy;
  return c;
}

bool Camera::IsValid() const {
  return width > 0 && height > 0 && std::isfinite(fx) && std::isfinite(fy) && fx > 0 && fy > 0 &&
         std::isfinite(cx) && std::isfinite(cy) && R.allFinite() && t.allFinite() &&
         std::abs(R.determinant() - 1.0) < 1e-6;
}

Camera LookAtCamera(const Eigen::Vector3d& center, const Eigen::Vector3d& target,
                    const Eigen::Vector3d& up, int width, int height, double fx, double fy) {
  const Eigen::Vector3d z = (target - center).normalized();    // forward
  Eigen::Vector3d x = z.cross(up);                             // right, so that y = z x x is down
  if (x.norm() < 1e-9) x = z.cross(Eigen::Vector3d::UnitX());  // looking along `up`
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Camera c;
  c.width = width;
  c.height = height;
  c.fx = fx;
  c.fy = fy;
  c.cx = width / 2.0;
  c.cy = height / 2.0;
  c.R.row(0) = x.transpose();
  c.R.row(1) = y.transpose();
  c.R.row(2) = z.transpose();
  c.t = -c.R * center;
  return c;
}

}  // namespace mgsr
