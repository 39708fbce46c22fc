#include "mgsr/core/lens.h"

#include <cmath>
#include <cstdio>

namespace mgsr {

bool Lens::IsPinhole() const {
  if (kind == Kind::kPinhole) return true;
  for (double v : k)
    if (v != 0) return false;
  return p1 == 0 && p2 == 0;
}

Eigen::Vector2d Lens::Distort(const Eigen::Vector2d& xy) const {
  const double x = xy.x(), y = xy.y(), r2 = x * x + y * y;
  if (kind == Kind::kRadial) {
    const double num = 1 + r2 * (k[0] + r2 * (k[1] + r2 * k[2]));
    const double den = 1 + r2 * (k[3] + r2 * (k[4] + r2 * k[5]));
    const double radial = num / den;
    return {x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y};
  }
  if (kind == Kind::kFisheye) {
    const double r = std::sqrt(r2);
    if (r < 1e-12) return xy;
    const double theta = std::atan(r), t2 = theta * theta;
    const double theta_d = theta * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
    return xy * (theta_d / r);
  }
  return xy;
}

bool Lens::Undistort(const Eigen::Vector2d& distorted, Eigen::Vector2d* xy) const {
  if (IsPinhole()) {
    *xy = distorted;
    return true;
  }
  // Newton on Distort(p) = distorted with a numeric Jacobian; the distorted point is the start.
  Eigen::Vector2d p = distorted;
  constexpr double h = 1e-7;
  for (int it = 0; it < 50; ++it) {
    const Eigen::Vector2d f = Distort(p) - distorted;
    if (f.norm() < 1e-13) break;
    Eigen::Matrix2d J;
    J.col(0) = (Distort(p + Eigen::Vector2d(h, 0)) - Distort(p - Eigen::Vector2d(h, 0))) / (2 * h);
    J.col(1) = (Distort(p + Eigen::Vector2d(0, h)) - Distort(p - Eigen::Vector2d(0, h))) / (2 * h);
    const double det = J(0, 0) * J(1, 1) - J(0, 1) * J(1, 0);
    if (!(std::abs(det) > 1e-12)) return false;
    Eigen::Vector2d step((J(1, 1) * f.x() - J(0, 1) * f.y()) / det,
                         (J(0, 0) * f.y() - J(1, 0) * f.x()) / det);
    // Damped: never jump more than the point's own distance from the centre in one step.
    const double limit = std::max(0.5, p.norm());
    if (step.norm() > limit) step *= limit / step.norm();
    p -= step;
    if (!p.allFinite()) return false;
  }
  if (!((Distort(p) - distorted).norm() < 1e-9)) return false;
  *xy = p;
  return true;
}

std::string Lens::CoefficientText() const {
  std::string out;
  char buffer[48];
  const int count = kind == Kind::kFisheye ? 4 : 6;
  for (int i = 0; i < count; ++i) {
    if (k[i] == 0) continue;
    std::snprintf(buffer, sizeof(buffer), "%sk%d %.4g", out.empty() ? "" : ", ", i + 1, k[i]);
    out += buffer;
  }
  for (const auto& [name, v] : {std::pair<const char*, double>{"p1", p1}, {"p2", p2}}) {
    if (v == 0) continue;
    std::snprintf(buffer, sizeof(buffer), "%s%s %.4g", out.empty() ? "" : ", ", name, v);
    out += buffer;
  }
  return out.empty() ? "no distortion" : out;
}

Status LensFromColmap(const std::string& model, const double* q, int n, int width, int height,
                      Lens* lens) {
  Lens l;
  l.model = model;
  l.width = width;
  l.height = height;
  // (focal parameters, then the distortion coefficients in COLMAP's order) per model.
  const auto need = [&](int count) {
    return n == count ? Status::Ok()
                      : Status::Error("camera model " + model + " takes " + std::to_string(count) +
                                      " parameters, not " + std::to_string(n));
  };
  if (model == "SIMPLE_PINHOLE" || model == "SIMPLE_RADIAL" || model == "RADIAL" ||
      model == "SIMPLE_RADIAL_FISHEYE" || model == "RADIAL_FISHEYE") {
    const bool two = model == "RADIAL" || model == "RADIAL_FISHEYE";
    MGSR_RETURN_IF_ERROR(need(model == "SIMPLE_PINHOLE" ? 3 : two ? 5 : 4));
    l.fx = l.fy = q[0];
    l.cx = q[1];
    l.cy = q[2];
    if (model != "SIMPLE_PINHOLE") {
      l.kind =
          model.find("FISHEYE") != std::string::npos ? Lens::Kind::kFisheye : Lens::Kind::kRadial;
      l.k[0] = q[3];
      if (two) l.k[1] = q[4];
    }
  } else if (model == "PINHOLE" || model == "OPENCV" || model == "OPENCV_FISHEYE" ||
             model == "FULL_OPENCV") {
    MGSR_RETURN_IF_ERROR(need(model == "PINHOLE" ? 4 : model == "FULL_OPENCV" ? 12 : 8));
    l.fx = q[0];
    l.fy = q[1];
    l.cx = q[2];
    l.cy = q[3];
    if (model == "OPENCV" || model == "FULL_OPENCV") {
      // COLMAP: k1 k2 p1 p2 [k3 k4 k5 k6]
      l.kind = Lens::Kind::kRadial;
      l.k[0] = q[4];
      l.k[1] = q[5];
      l.p1 = q[6];
      l.p2 = q[7];
      for (int i = 0; model == "FULL_OPENCV" && i < 4; ++i) l.k[2 + i] = q[8 + i];
    } else if (model == "OPENCV_FISHEYE") {
      l.kind = Lens::Kind::kFisheye;
      for (int i = 0; i < 4; ++i) l.k[i] = q[4 + i];
    }
  } else {
    return Status::Error("camera model " + model +
                         " is not supported (PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL, "
                         "OPENCV, FULL_OPENCV, OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE, "
                         "RADIAL_FISHEYE are); undistort the photos with colmap image_undistorter");
  }
  *lens = l;
  return Status::Ok();
}

}  // namespace mgsr
