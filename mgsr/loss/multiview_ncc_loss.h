// Multi-view photometric consistency through the rendered plane (after PGSR's patch term): the
// rendered depth D and normal N at a pixel p define a plane; a grey patch of the view's photo
// around p, mapped into a neighbouring view by the homography that plane induces, must look the
// same there. The normalised cross-correlation of the two patches is blind to each view's exposure
// and gain, so the term rewards geometry that several photos agree on, which a smoothness prior or
// one photo's shading cannot fake.
//
//   L = sum over sampled pixels p (a grid of `stride`) and neighbours n of (1 - NCC(a_p, b_pn)) / M
//
// On a large image the grid widens so that it holds at most `max_centres` pixels: the cost of a
// step stays bounded (PGSR samples a fixed number of pixels for the same reason) instead of growing
// with the photo's size.
//
// a_p: the view's grey photo at the (2r + 1)^2 pixel centres q around p; b_pn: the neighbour's grey
// photo, bilinearly sampled at H_pn q. With the plane n_c . X = d in the view's camera frame (n_c
// the unit normal turned into the camera, d = n_c . X_p, X_p = D r_p), a pixel q's ray r_q maps to
// the neighbour's camera point R_rel r_q + t_rel (n_c . r_q) / d, i.e. H = K_n (R_rel + t_rel
// n_c^T / d) K^-1. Gradients reach D and N of the centre pixel only (the plane is the centre's).
// M is the number of sampled foreground pixels (alpha and mask at least 0.5, both constants)
// times the number of neighbours. A pair does not count where the patch leaves the neighbour's
// frame, the plane is seen edge-on, the view's patch has no texture (its variance below
// `min_variance`), the patch does not lie on the centre's plane in the view's own render (a pixel
// of it uncovered, or its rendered depth more than `max_plane_offset_px` pixel footprints off the
// plane: at an outline, a step, or a surface curved within the patch, where one homography maps
// the patch onto the wrong pixels), or, when the neighbours' rendered depth is given, the centre is
// occluded there (forward-backward reprojection error above `max_reprojection_px`), or the two
// patches do not correlate (1 - NCC above `max_pair_loss`: an outlier, such as a highlight that
// moves between the views, rather than evidence about the plane).
#pragma once

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"
#include "mgsr/loss/multiview_geometry.h"
#include "mgsr/loss/parallel_pixels.h"

namespace mgsr {

struct MultiviewNccConfig {
  int patch_radius = 3;              // (2r + 1)^2 samples per patch
  int stride = 3;                    // pixel grid of the patch centres
  int max_centres = 16384;           // the grid widens beyond `stride` to keep at most this many
  double min_variance = 1e-4;        // grey variance below which a patch has no texture
  double min_alpha = 0.5;            // centres where the render covers the pixel
  double max_reprojection_px = 1.0;  // occlusion test (check_occlusion)
  // The patch must lie on the centre's plane: every pixel covered (alpha and mask at least
  // min_alpha) and within this many pixel footprints of the plane (<= 0: no test).
  double max_plane_offset_px = 1.0;
  // true: the patch's rendered points must lie within max_plane_offset_px of the plane fitted to
  // them (least squares) rather than of the plane of the centre's rendered normal; the test then
  // asks only whether the patch is one surface (no outline, step or tight curve), not whether the
  // rendered normal already agrees with the depth, which is what the term is to teach it.
  bool fit_plane = false;
  // Render each neighbour's depth every step and skip centres occluded there. Off by default: with
  // the outlier test below it changed no mesh by more than the spread between runs, and the two
  // renders cost a quarter of the run (docs/geometry.md, "The normal TV, and the patch term by
  // default").
  bool check_occlusion = false;
  // Pairs whose patches correlate this badly (1 - NCC above it) are outliers, not evidence: a
  // highlight or reflection that moves between the views, an occluder the depth test missed.
  // They are left out, as in PGSR; >= 2 keeps every pair.
  double max_pair_loss = 0.9;
};

class MultiviewNccLoss : public LossTermImpl<MultiviewNccLoss> {
 public:
  explicit MultiviewNccLoss(const MultiviewNccConfig& config = {}) : c_(config) {}
  std::string Name() const override { return "multiview_ncc"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kDepth, Buffer::kNormal}; }
  std::vector<Buffer> ConstantInputs() const override { return {Buffer::kAlpha}; }
  bool ReadsNeighbourDepth() const override { return c_.check_occlusion; }
  bool ReadsNeighbours() const override { return true; }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireSurfaceGeometry(Name(), in, t));
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), "grey photo", t.gray, in.Get(Buffer::kDepth), 1));
    for (int k = 0; k < t.num_neighbours; ++k) {
      if (t.neighbours[k].camera == nullptr || t.neighbours[k].gray == nullptr)
        return Status::Error(Name() + ": neighbour " + std::to_string(k) + " has no photo");
    }
    return Status::Ok();
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    return Run<T, false>(in, t, scale, grad, nullptr);
  }

  // How well the photos agree with the rendered plane at each centre of the grid (Stride(w, h);
  // the centre of cell (cx, cy) is pixel (cx s, cy s), row-major, ceil(w / s) x ceil(h / s)): the
  // mean over the neighbours compared of max(0, NCC), outlier pairs included, and 0 where no
  // neighbour could be compared (no texture, off the plane, outside the frames, background).
  // Resizes `agreement`; the value of the term is returned as by Compute.
  template <typename T>
  double Agreement(const RenderBuffersT<T>& in, const TargetsT<T>& t,
                   std::vector<double>* agreement) const {
    const ImageT<T>& D = *in.Get(Buffer::kDepth);
    const int s = Stride(D.width(), D.height());
    agreement->assign(static_cast<size_t>(multiview::GridCells(D.width(), s)) *
                          multiview::GridCells(D.height(), s),
                      0.0);
    return Run<T, true>(in, t, 0.0, nullptr, agreement->data());
  }

  const MultiviewNccConfig& config() const { return c_; }
  // The centres' grid on a w x h image: `stride`, or wider where that grid would hold more than
  // `max_centres` pixels.
  int Stride(int w, int h) const {
    int s = std::max(1, c_.stride);
    const double pixels = static_cast<double>(w) * h;
    while (c_.max_centres > 0 && pixels / (static_cast<double>(s) * s) > c_.max_centres) ++s;
    return s;
  }

 private:
  // The term (and its gradient when `grad` is not null), and with kAgreement each centre's
  // agreement into `agreement` (Agreement's layout; the term's own evaluation is compiled
  // without it).
  template <typename T, bool kAgreement>
  double Run(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
             RenderGradientsT<T>* grad, double* agreement) const;

  // Whether the (2r + 1)^2 patch around (x, y) lies on the plane of the centre (camera-frame unit
  // normal `nc`, z-depth `depth`) in the view's own render: every pixel covered and its rendered
  // point within `tolerance` (scene units) of the plane (with fit_plane, of the patch's own fitted
  // plane: PatchOnFittedPlane). A selection, not a weight: the buffers it reads are not
  // differentiated through it.
  template <typename T>
  bool PatchOnPlane(const ImageT<T>& D, const ImageT<T>& A, const ImageT<T>* mask, int x, int y,
                    int r, double depth, const Eigen::Vector3d& nc,
                    const std::vector<Eigen::Vector3d>& rays, double tolerance) const;

  // fit_plane's test: every pixel covered and its rendered point within `tolerance` of the
  // least-squares plane of the patch's points.
  template <typename T>
  bool PatchOnFittedPlane(const ImageT<T>& D, const ImageT<T>& A, const ImageT<T>* mask, int x,
                          int y, int r, const std::vector<Eigen::Vector3d>& rays,
                          double tolerance) const;

  MultiviewNccConfig c_;
};

// --- implementation ---------------------------------------------------------------------------

template <typename T, bool kAgreement>
double MultiviewNccLoss::Run(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                             RenderGradientsT<T>* grad, double* agreement) const {
  const ImageT<T>& D = *in.Get(Buffer::kDepth);
  const ImageT<T>& N = *in.Get(Buffer::kNormal);
  const ImageT<T>& A = *in.Get(Buffer::kAlpha);
  const ImageT<T>& G = *t.gray;
  const Camera& cam = *in.camera;
  const int w = D.width(), h = D.height();
  const int r = std::max(0, c_.patch_radius), stride = Stride(w, h);
  const int m = (2 * r + 1) * (2 * r + 1);
  const int rows = multiview::GridCells(h, stride);
  const int cols = multiview::GridCells(w, stride);
  // The sampled foreground centres: the normaliser (constant: alpha and the mask are constants).
  const size_t centres = multiview::CountSampledPixels(A, t.mask, stride, c_.min_alpha);
  if (centres == 0 || t.num_neighbours == 0) return 0.0;
  const double inv_count = 1.0 / (static_cast<double>(centres) * t.num_neighbours);
  T* gD = grad != nullptr ? grad->Get(Buffer::kDepth, D).data() : nullptr;
  T* gN[3] = {nullptr, nullptr, nullptr};
  if (grad != nullptr) {
    ImageT<T>& g = grad->Get(Buffer::kNormal, N);
    for (int k = 0; k < 3; ++k) gN[k] = g.plane(k);
  }
  // Per-row sums, added in row order: the same value whatever the thread count.
  static thread_local std::vector<double> row_sums;
  row_sums.assign(rows, 0.0);
  // A pointer, not the thread_local, into the parallel region: there each thread naming
  // `row_sums` would get its own, empty one.
  double* const sums = row_sums.data();
  const Eigen::Matrix3d K_inv = (Eigen::Matrix3d() << 1.0 / cam.fx, 0, -cam.cx / cam.fx, 0,
                                 1.0 / cam.fy, -cam.cy / cam.fy, 0, 0, 1)
                                    .finished();
  // Each neighbour's pose relative to this view, once per call rather than per pixel: a camera
  // point X maps to R_rel X + t_rel there, and tau = K_nb t_rel is the homography's plane part.
  struct RelativePose {
    Eigen::Matrix3d R_rel;
    Eigen::Vector3d tau;
  };
  std::array<RelativePose, kMaxNeighbours> poses;
  for (int nbi = 0; nbi < t.num_neighbours; ++nbi) {
    const Camera& nc_cam = *t.neighbours[nbi].camera;
    RelativePose& pose = poses[nbi];
    pose.R_rel = nc_cam.R * cam.R.transpose();
    const Eigen::Vector3d t_rel = nc_cam.t - pose.R_rel * cam.t;
    pose.tau = Eigen::Vector3d(nc_cam.fx * t_rel.x() + nc_cam.cx * t_rel.z(),
                               nc_cam.fy * t_rel.y() + nc_cam.cy * t_rel.z(), t_rel.z());
  }
#pragma omp parallel for schedule(dynamic, 4) if (static_cast <int64_t>(w) * h >= kParallelPixels)
  for (int row = 0; row < rows; ++row) {
    const int y = row * stride;
    // Each thread's patch scratch, kept between calls (no allocation once sized).
    static thread_local std::vector<double> scratch;
    static thread_local std::vector<Eigen::Vector3d> rays;
    scratch.resize(7 * static_cast<size_t>(m));
    rays.resize(m);
    double* const a = scratch.data();
    double* const b = a + m;
    double* const dbu = b + m;
    double* const dbv = dbu + m;
    double* const rho = dbv + m;
    double* const dP_drho = rho + m;  // 2 m
    double sum = 0;
    for (int x = 0; x < w; x += stride) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (!multiview::SampledPixel(A, t.mask, i, c_.min_alpha)) continue;
      if (x - r < 0 || y - r < 0 || x + r >= w || y + r >= h) continue;
      const double depth = D.data()[i];
      const Eigen::Vector3d Nw(N.plane(0)[i], N.plane(1)[i], N.plane(2)[i]);
      const double norm = Nw.norm();
      if (!(depth > 0) || !(norm > 1e-8)) continue;
      const Eigen::Vector3d nw = Nw / norm;
      const Eigen::Vector3d nc = cam.R * nw;
      // The view's patch and its rays (camera frame, z = 1).
      double mean_a = 0;
      for (int dy = -r, k = 0; dy <= r; ++dy) {
        for (int dx = -r; dx <= r; ++dx, ++k) {
          a[k] = G.data()[static_cast<size_t>(y + dy) * w + (x + dx)];
          mean_a += a[k];
          rays[k] = K_inv * Eigen::Vector3d(x + dx + 0.5, y + dy + 0.5, 1.0);
        }
      }
      mean_a /= m;
      // The tolerance in scene units: a pixel at z-depth z spans z / fx.
      if (c_.max_plane_offset_px > 0 && !PatchOnPlane(D, A, t.mask, x, y, r, depth, nc, rays,
                                                      c_.max_plane_offset_px * depth / cam.fx))
        continue;
      double var_a = 0;
      for (int k = 0; k < m; ++k) {
        a[k] -= mean_a;
        var_a += a[k] * a[k];
      }
      var_a /= m;
      if (var_a < c_.min_variance) continue;
      const int centre = m / 2;
      const double s0 = nc.dot(rays[centre]);
      // A plane seen edge-on maps the patch onto a line: nothing to compare.
      if (std::fabs(s0) < 0.1 * rays[centre].norm()) continue;
      double dL_dD = 0;
      Eigen::Vector3d dL_dnc = Eigen::Vector3d::Zero();
      double agreement_sum = 0;
      int compared = 0;
      for (int nbi = 0; nbi < t.num_neighbours; ++nbi) {
        const NeighbourViewT<T>& nb = t.neighbours[nbi];
        const Camera& nc_cam = *nb.camera;
        if (c_.check_occlusion && nb.depth != nullptr) {
          double err;
          if (!multiview::ForwardBackward(cam, nc_cam, *nb.depth, Eigen::Vector2d(x + 0.5, y + 0.5),
                                          depth, &err, nullptr) ||
              err > c_.max_reprojection_px)
            continue;
        }
        const Eigen::Matrix3d& R_rel = poses[nbi].R_rel;
        const Eigen::Vector3d& tau = poses[nbi].tau;
        bool inside = true;
        double mean_b = 0;
        for (int k = 0; k < m && inside; ++k) {
          rho[k] = nc.dot(rays[k]) / (depth * s0);
          const Eigen::Vector3d u = R_rel * rays[k];
          const Eigen::Vector3d q(nc_cam.fx * u.x() + nc_cam.cx * u.z() + tau.x() * rho[k],
                                  nc_cam.fy * u.y() + nc_cam.cy * u.z() + tau.y() * rho[k],
                                  u.z() + tau.z() * rho[k]);
          if (!(q.z() > 1e-9)) {
            inside = false;
            break;
          }
          const double px = q.x() / q.z(), py = q.y() / q.z();
          dP_drho[2 * k] = (tau.x() - px * tau.z()) / q.z();
          dP_drho[2 * k + 1] = (tau.y() - py * tau.z()) / q.z();
          inside = multiview::Bilinear(*nb.gray, px, py, &b[k], &dbu[k], &dbv[k]);
          mean_b += b[k];
        }
        if (!inside) continue;
        mean_b /= m;
        double cov = 0, var_b = 0;
        for (int k = 0; k < m; ++k) {
          b[k] -= mean_b;
          cov += a[k] * b[k];
          var_b += b[k] * b[k];
        }
        cov /= m;
        var_b /= m;
        const double S = std::sqrt(var_a * var_b + 1e-8);
        const double ncc = cov / S;
        if constexpr (kAgreement) {
          agreement_sum += std::max(0.0, ncc);
          ++compared;
        }
        if (1.0 - ncc > c_.max_pair_loss) continue;
        sum += 1.0 - ncc;
        if (gD == nullptr) continue;
        // d(1 - NCC)/d b_k = -(a_k / (m S) - cov var_a b_k / (m S^3)).
        const double c1 = -1.0 / (m * S), c2 = cov * var_a / (m * S * S * S);
        for (int k = 0; k < m; ++k) {
          const double dL_db = c1 * a[k] + c2 * b[k];
          const double dL_drho = dL_db * (dbu[k] * dP_drho[2 * k] + dbv[k] * dP_drho[2 * k + 1]);
          // rho_k = (n . r_k) / (D (n . r_0)).
          dL_dD += dL_drho * (-rho[k] / depth);
          dL_dnc += dL_drho * (rays[k] - (nc.dot(rays[k]) / s0) * rays[centre]) / (depth * s0);
        }
      }
      if (kAgreement && compared > 0)
        agreement[static_cast<size_t>(row) * cols + x / stride] = agreement_sum / compared;
      if (gD == nullptr) continue;
      const double gain = scale * inv_count;
      gD[i] += static_cast<T>(gain * dL_dD);
      // n_c = R n_w, n_w = N / |N|: dL/dN = (I - n_w n_w^T) / |N| R^T dL/dn_c.
      const Eigen::Vector3d g_w = cam.R.transpose() * dL_dnc;
      const Eigen::Vector3d g_N = (g_w - nw * nw.dot(g_w)) / norm;
      for (int k = 0; k < 3; ++k) gN[k][i] += static_cast<T>(gain * g_N[k]);
    }
    sums[row] = sum;
  }
  double total = 0;
  for (int row = 0; row < rows; ++row) total += sums[row];
  return total * inv_count;
}

template <typename T>
bool MultiviewNccLoss::PatchOnPlane(const ImageT<T>& D, const ImageT<T>& A, const ImageT<T>* mask,
                                    int x, int y, int r, double depth, const Eigen::Vector3d& nc,
                                    const std::vector<Eigen::Vector3d>& rays,
                                    double tolerance) const {
  if (c_.fit_plane) return PatchOnFittedPlane(D, A, mask, x, y, r, rays, tolerance);
  const int w = D.width(), side = 2 * r + 1;
  const double plane = depth * nc.dot(rays[side * side / 2]);  // nc . X for X on the plane
  for (int dy = -r, k = 0; dy <= r; ++dy) {
    for (int dx = -r; dx <= r; ++dx, ++k) {
      const size_t q = static_cast<size_t>(y + dy) * w + (x + dx);
      if (!multiview::SampledPixel(A, mask, q, c_.min_alpha)) return false;
      if (!(std::fabs(static_cast<double>(D.data()[q]) * nc.dot(rays[k]) - plane) <= tolerance))
        return false;
    }
  }
  return true;
}

template <typename T>
bool MultiviewNccLoss::PatchOnFittedPlane(const ImageT<T>& D, const ImageT<T>& A,
                                          const ImageT<T>* mask, int x, int y, int r,
                                          const std::vector<Eigen::Vector3d>& rays,
                                          double tolerance) const {
  const int w = D.width(), side = 2 * r + 1;
  // The points' centroid and scatter; the plane's normal is the scatter's least eigenvector.
  const int m = side * side;
  static thread_local std::vector<Eigen::Vector3d> points;
  points.resize(m);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int dy = -r, k = 0; dy <= r; ++dy) {
    for (int dx = -r; dx <= r; ++dx, ++k) {
      const size_t q = static_cast<size_t>(y + dy) * w + (x + dx);
      if (!multiview::SampledPixel(A, mask, q, c_.min_alpha)) return false;
      points[k] = static_cast<double>(D.data()[q]) * rays[k];
      mean += points[k];
    }
  }
  mean /= m;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& X : points) scatter += (X - mean) * (X - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  const Eigen::Vector3d n_fit = eig.eigenvectors().col(0);
  for (const Eigen::Vector3d& X : points) {
    if (!(std::fabs(n_fit.dot(X - mean)) <= tolerance)) return false;
  }
  return true;
}

}  // namespace mgsr
