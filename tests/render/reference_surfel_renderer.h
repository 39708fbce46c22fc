// A slow, independent reference of the 2DGS-branch render for tests: double precision, one pixel
// at a time over every surfel sorted by depth, no tiles, written from method.md 3 and the
// rules of rasterize_surfels.h; it shares no code with the renderer.
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/model/surfel_model.h"
#include "reference_gaussian_renderer.h"  // ReferenceShColor

namespace mgsr::testing {

struct SurfelModelD {
  int max_sh_degree = 3;
  std::vector<double> means, log_scales, quats, opacity_logits, sh;
  size_t size() const { return opacity_logits.size(); }
  int sh_coeffs() const { return (max_sh_degree + 1) * (max_sh_degree + 1); }
  explicit SurfelModelD(const SurfelModel& m)
      : max_sh_degree(m.max_sh_degree),
        means(m.means.begin(), m.means.end()),
        log_scales(m.log_scales.begin(), m.log_scales.end()),
        quats(m.quats.begin(), m.quats.end()),
        opacity_logits(m.opacity_logits.begin(), m.opacity_logits.end()),
        sh(m.sh.begin(), m.sh.end()) {}
};

struct ReferenceSurfelRender {
  std::vector<double> color, normal, normal_world;  // 3 x H x W planar
  std::vector<double> depth, alpha, median, distortion;
};

// `area_preserving`: the low-pass floor's opacity scaled by min(1, 2 |det J|), det J = det M / z^3
// (SurfelLowPass::kAreaPreserving); false: the reference's full-opacity floor.
template <typename Model>
ReferenceSurfelRender RenderSurfelsReference(const Model& m, const Camera& cam, int sh_degree,
                                             const double bg[3], bool area_preserving,
                                             double filter_sigma = 0.70710678118654752,
                                             const std::vector<double>* bg_image = nullptr) {
  const double inv_square = 1 / (filter_sigma * filter_sigma);
  struct S {
    Eigen::Matrix3d M;  // rows T_u, T_v, T_w
    Eigen::Vector2d center;
    double radius, depth, o;
    Eigen::Vector3d n, c;
  };
  std::vector<S> splats;
  Eigen::Matrix3d K;
  K << cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1;
  for (size_t i = 0; i < m.size(); ++i) {
    Eigen::Quaterniond q(m.quats[4 * i], m.quats[4 * i + 1], m.quats[4 * i + 2],
                         m.quats[4 * i + 3]);
    const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
    const Eigen::Vector3d p(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
    const double su = std::exp(static_cast<double>(m.log_scales[2 * i]));
    const double sv = std::exp(static_cast<double>(m.log_scales[2 * i + 1]));
    Eigen::Matrix3d A;
    A.col(0) = cam.R * (su * R.col(0));
    A.col(1) = cam.R * (sv * R.col(1));
    A.col(2) = cam.R * p + cam.t;
    if (!(A(2, 2) > 0.2)) continue;
    S s;
    s.M = K * A;
    s.depth = A(2, 2);
    s.n = cam.R * R.col(2);
    const double cosine = -A.col(2).dot(s.n);
    if (cosine == 0) continue;
    if (cosine < 0) s.n = -s.n;
    const Eigen::Vector3d Tu = s.M.row(0), Tv = s.M.row(1), Tw = s.M.row(2);
    const Eigen::Vector3d t(9, 9, -1);
    const double d = t.dot(Tw.cwiseProduct(Tw));
    if (d == 0) continue;
    const Eigen::Vector3d f = t / d;
    s.center = {f.dot(Tu.cwiseProduct(Tw)), f.dot(Tv.cwiseProduct(Tw))};
    const double hx =
        std::sqrt(std::max(1e-4, s.center.x() * s.center.x() - f.dot(Tu.cwiseProduct(Tu))));
    const double hy =
        std::sqrt(std::max(1e-4, s.center.y() * s.center.y() - f.dot(Tv.cwiseProduct(Tv))));
    // The renderer computes the radius in float; ceil() agrees away from integers.
    s.radius = std::ceil(std::max(std::max(hx, hy), 3 * filter_sigma));
    s.o = 1 / (1 + std::exp(-static_cast<double>(m.opacity_logits[i])));
    ReferenceShColor(std::min(sh_degree, m.max_sh_degree), &m.sh[i * m.sh_coeffs() * 3],
                     (p - cam.Center()).normalized(), s.c.data());
    splats.push_back(s);
  }
  std::stable_sort(splats.begin(), splats.end(),
                   [](const S& a, const S& b) { return a.depth < b.depth; });
  const double near = 0.2, far = 100;
  const size_t np = static_cast<size_t>(cam.width) * cam.height;
  ReferenceSurfelRender r;
  r.color.assign(3 * np, 0);
  r.normal.assign(3 * np, 0);
  r.normal_world.assign(3 * np, 0);
  r.depth.assign(np, 0);
  r.alpha.assign(np, 0);
  r.median.assign(np, 0);
  r.distortion.assign(np, 0);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const double px = x + 0.5, py = y + 0.5;
      double T = 1, D = 0, zmed = 0, M1 = 0, M2 = 0, dist = 0;
      Eigen::Vector3d C = Eigen::Vector3d::Zero(), N = Eigen::Vector3d::Zero();
      for (const S& s : splats) {
        if (std::abs(px - s.center.x()) > s.radius || std::abs(py - s.center.y()) > s.radius)
          continue;
        const Eigen::Vector3d k = px * s.M.row(2) - s.M.row(0);
        const Eigen::Vector3d l = py * s.M.row(2) - s.M.row(1);
        const Eigen::Vector3d p = k.cross(l);
        if (p.z() == 0) continue;
        const double u = p.x() / p.z(), v = p.y() / p.z();
        const double rho3d = u * u + v * v;
        double rho2d = inv_square * ((s.center.x() - px) * (s.center.x() - px) +
                                     (s.center.y() - py) * (s.center.y() - py));
        if (area_preserving) {
          const double area = inv_square * std::abs(s.M.determinant()) / std::pow(s.M(2, 2), 3);
          if (area < 1) rho2d -= 2 * std::log(std::max(area, 1e-6));
        }
        // Depth: where the ray meets the plane on the disk, the centre's depth where the screen
        // low-pass draws the surfel.
        const double z = rho3d <= rho2d ? s.M(2, 0) * u + s.M(2, 1) * v + s.M(2, 2) : s.M(2, 2);
        if (z < near) continue;
        const double G = std::exp(-0.5 * std::min(rho3d, rho2d));
        const double a = std::min(0.99, s.o * G);
        if (a < 1.0 / 255.0) continue;
        if (T * (1 - a) < 1e-4) break;
        const double w = a * T;
        C += w * s.c;
        D += w * z;
        N += w * s.n;
        if (T > 0.5) zmed = z;
        const double mz = far / (far - near) * (1 - near / z);
        dist += w * (mz * mz * (1 - T) + M2 - 2 * mz * M1);
        M1 += w * mz;
        M2 += w * mz * mz;
        T *= 1 - a;
      }
      const size_t q = static_cast<size_t>(y) * cam.width + x;
      const Eigen::Vector3d Nw = cam.R.transpose() * N;
      for (int c = 0; c < 3; ++c) {
        r.color[c * np + q] = C[c] + T * (bg_image != nullptr ? (*bg_image)[c * np + q] : bg[c]);
        r.normal[c * np + q] = N[c];
        r.normal_world[c * np + q] = Nw[c];
      }
      const double A = 1 - T;
      r.alpha[q] = A;
      r.depth[q] = A >= 1e-4 ? D / A : 0;
      r.median[q] = zmed;
      r.distortion[q] = dist;
    }
  }
  return r;
}

}  // namespace mgsr::testing
