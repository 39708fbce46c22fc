// Lens: the intrinsics of a photo as its capture tool describes them, lens distortion included.
// The solver trains on pinhole cameras (Camera); a distorted photo is resampled once to a pinhole
// image (mgsr/io/undistort.h), and Lens says how. Conventions are COLMAP's: pixel (u, v) of the
// normalised point (x, y) is (fx * x + cx, fy * y + cy), the top-left pixel's centre at (0.5, 0.5).
//
// Two families cover every model COLMAP and nerfstudio write:
// - kRadial, OpenCV's standard model (COLMAP SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV; nerfstudio
//   OPENCV): with r^2 = x^2 + y^2,
//     radial = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
//     x_d = x radial + 2 p1 x y + p2 (r^2 + 2 x^2),  y_d = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y
// - kFisheye, OpenCV's equidistant fisheye (COLMAP OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE,
//   RADIAL_FISHEYE; nerfstudio OPENCV_FISHEYE): theta = atan(r),
//     theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8),
//     (x_d, y_d) = (x, y) theta_d / r
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>

#include "mgsr/core/status.h"

namespace mgsr {

struct Lens {
  enum class Kind { kPinhole, kRadial, kFisheye };
  Kind kind = Kind::kPinhole;
  std::string model = "PINHOLE";  // the name the input gave (for messages and the log)
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  // kRadial: k1..k6 (k4..k6 the rational denominator); kFisheye: k1..k4.
  std::array<double, 6> k{};
  double p1 = 0, p2 = 0;  // tangential (kRadial only)

  // No distortion at all (every coefficient zero), whatever the model's name.
  bool IsPinhole() const;
  // Normalised undistorted -> normalised distorted coordinates.
  Eigen::Vector2d Distort(const Eigen::Vector2d& xy) const;
  // The inverse of Distort (Newton's method; exact to ~1e-12 inside the image). False where it
  // does not converge (beyond a fisheye's field of view, or where the model folds over).
  bool Undistort(const Eigen::Vector2d& distorted, Eigen::Vector2d* xy) const;
  // Coefficients as "k1 -0.12, k2 0.03, p1 0.001" (the non-zero ones) for the log.
  std::string CoefficientText() const;
};

// The lens of a COLMAP camera model by name and its parameter list (COLMAP's order). Models
// without an equivalent here (FOV, THIN_PRISM_FISHEYE, unknown) are refused, naming the model.
Status LensFromColmap(const std::string& model, const double* params, int num_params, int width,
                      int height, Lens* lens);

}  // namespace mgsr
