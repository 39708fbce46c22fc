// Helpers of the multi-view terms: bilinear samples with their gradient, and the forward-backward
// reprojection of a pixel's depth through a neighbour's depth. Pixel coordinates follow COLMAP
// (pixel (x, y) covers [x, x + 1) x [y, y + 1), its centre at x + 0.5).
#pragma once

#include <Eigen/Core>
#include <cmath>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"

namespace mgsr {
namespace multiview {

// The pixels a multi-view term samples: a grid of `stride` where the render covers the pixel
// (alpha at least `min_alpha`) inside the mask (at least 0.5; no mask: everywhere). Both are
// constants, so the count is the terms' normaliser.
template <typename T>
bool SampledPixel(const ImageT<T>& alpha, const ImageT<T>* mask, size_t i, double min_alpha) {
  return alpha.data()[i] >= min_alpha && (mask == nullptr || mask->data()[i] >= 0.5);
}
// Grid centres along a side of n pixels at the grid's stride s: 0, s, 2 s, ... below n.
inline int GridCells(int n, int s) { return (n + s - 1) / s; }
template <typename T>
size_t CountSampledPixels(const ImageT<T>& alpha, const ImageT<T>* mask, int stride,
                          double min_alpha) {
  size_t count = 0;
  for (int y = 0; y < alpha.height(); y += stride)
    for (int x = 0; x < alpha.width(); x += stride)
      count += SampledPixel(alpha, mask, static_cast<size_t>(y) * alpha.width() + x, min_alpha);
  return count;
}

// Bilinear sample of channel 0 of `img` at pixel coordinates (u, v), with d value / d (u, v).
// False (nothing written) where the four taps are not all inside the image.
template <typename T>
bool Bilinear(const ImageT<T>& img, double u, double v, double* value, double* du, double* dv) {
  const double x = u - 0.5, y = v - 0.5;
  const double fx = std::floor(x), fy = std::floor(y);
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  if (x0 < 0 || y0 < 0 || x0 + 1 >= img.width() || y0 + 1 >= img.height()) return false;
  const double ax = x - fx, ay = y - fy;
  const T* row0 = img.data() + static_cast<size_t>(y0) * img.width() + x0;
  const T* row1 = row0 + img.width();
  const double a = row0[0], b = row0[1], c = row1[0], d = row1[1];
  const double top = a + (b - a) * ax, bottom = c + (d - c) * ax;
  *value = top + (bottom - top) * ay;
  if (du != nullptr) *du = (b - a) + ((d - c) - (b - a)) * ay;
  if (dv != nullptr) *dv = bottom - top;
  return true;
}

// The same for a depth map: also false where a tap has no depth (<= 0).
template <typename T>
bool BilinearDepth(const ImageT<T>& depth, double u, double v, double* value, double* du,
                   double* dv) {
  const double x = u - 0.5, y = v - 0.5;
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= depth.width() || y0 + 1 >= depth.height()) return false;
  const T* row0 = depth.data() + static_cast<size_t>(y0) * depth.width() + x0;
  const T* row1 = row0 + depth.width();
  if (!(row0[0] > 0) || !(row0[1] > 0) || !(row1[0] > 0) || !(row1[1] > 0)) return false;
  return Bilinear(depth, u, v, value, du, dv);
}

// The plane-induced homography: the plane through the point of reference pixel p (at z-depth D)
// with world normal n, seen from `ref`, maps reference pixel q to this pixel of `nb`:
// H = K_nb (R_rel + t_rel n_c^T / d) K_ref^-1, n_c = R_ref n, d = n_c . X_p. With
// rho_q = (n_c . r_q) / (D (n_c . r_p)) (r the camera rays at z = 1) it is
// K_nb (R_rel r_q + t_rel rho_q), the form the NCC term differentiates. False where the plane is
// seen edge-on at p or the point lands behind `nb`.
inline bool WarpThroughPlane(const Camera& ref, const Camera& nb, const Eigen::Vector2d& p,
                             double D, const Eigen::Vector3d& n_world, const Eigen::Vector2d& q,
                             Eigen::Vector2d* out) {
  const Eigen::Vector3d nc = ref.R * n_world;
  const Eigen::Vector3d rp = ref.PixelToRay(p.x(), p.y()), rq = ref.PixelToRay(q.x(), q.y());
  const double s0 = nc.dot(rp);
  if (std::fabs(s0) < 1e-12 || !(D > 0)) return false;
  const double rho = nc.dot(rq) / (D * s0);
  const Eigen::Matrix3d R_rel = nb.R * ref.R.transpose();
  const Eigen::Vector3d t_rel = nb.t - R_rel * ref.t;
  const Eigen::Vector3d y = R_rel * rq + t_rel * rho;
  if (!(y.z() > 1e-12)) return false;
  *out = nb.CameraToPixel(y);
  return true;
}

// d (pixel) / d (camera-space point) of `cam` at camera-space point x (2 x 3).
inline Eigen::Matrix<double, 2, 3> ProjectionJacobian(const Camera& cam, const Eigen::Vector3d& x) {
  Eigen::Matrix<double, 2, 3> J;
  J << cam.fx / x.z(), 0, -cam.fx * x.x() / (x.z() * x.z()), 0, cam.fy / x.z(),
      -cam.fy * x.y() / (x.z() * x.z());
  return J;
}

// Forward-backward reprojection of the reference pixel centre p (depth D along the camera ray of
// pixel p, z = D) through a neighbour's depth: the point goes to the neighbour, takes the depth the
// neighbour sees there, and comes back. `error` is |p' - p| in reference pixels; `d_error_d_depth`
// its derivative with respect to D (the neighbour's depth a constant field). False where the point
// leaves the neighbour's frame or depth, or where the way back does not land in front of the
// reference camera.
template <typename T>
bool ForwardBackward(const Camera& ref, const Camera& nb, const ImageT<T>& nb_depth,
                     const Eigen::Vector2d& p, double D, double* error, double* d_error_d_depth) {
  // Reference ray (world, camera z = 1) and the point.
  const Eigen::Matrix3d Rr_t = ref.R.transpose();
  const Eigen::Vector3d w = Rr_t * ref.PixelToRay(p.x(), p.y());
  const Eigen::Vector3d X = ref.Center() + D * w;
  // Into the neighbour.
  const Eigen::Vector3d xn = nb.WorldToCamera(X);
  if (!(xn.z() > 1e-9)) return false;
  const Eigen::Vector2d pn = nb.CameraToPixel(xn);
  double Dn, gu, gv;
  if (!BilinearDepth(nb_depth, pn.x(), pn.y(), &Dn, &gu, &gv)) return false;
  // Back from the neighbour's surface.
  const Eigen::Matrix3d Rn_t = nb.R.transpose();
  const Eigen::Vector3d wn = Rn_t * nb.PixelToRay(pn.x(), pn.y());
  const Eigen::Vector3d Xb = nb.Center() + Dn * wn;
  const Eigen::Vector3d xr = ref.WorldToCamera(Xb);
  if (!(xr.z() > 1e-9)) return false;
  const Eigen::Vector2d pb = ref.CameraToPixel(xr);
  const Eigen::Vector2d diff = pb - p;
  *error = diff.norm();
  if (d_error_d_depth == nullptr) return true;
  // d pn / d X (2x3) = J(xn) Rn; d X / d D = w.
  const Eigen::Vector2d dpn = ProjectionJacobian(nb, xn) * (nb.R * w);
  // d Xb / d pn (3x2) = wn (dDn/dpn)^T + Dn d wn / d pn, with d wn / d pn = Rn^T diag(1/fx, 1/fy).
  Eigen::Matrix<double, 3, 2> dXb;
  dXb.col(0) = wn * gu + Dn * Rn_t.col(0) / nb.fx;
  dXb.col(1) = wn * gv + Dn * Rn_t.col(1) / nb.fy;
  const Eigen::Vector2d dpb = ProjectionJacobian(ref, xr) * (ref.R * (dXb * dpn));
  *d_error_d_depth = *error > 1e-12 ? diff.dot(dpb) / *error : 0.0;
  return true;
}

}  // namespace multiview
}  // namespace mgsr
