// A slow, independent reference of the 3DGS-branch render for tests: double precision, one pixel
// at a time over every Gaussian sorted by depth, no tiles. It implements the documented rules of
// rasterize_gaussians.h (3-sigma square, per-chain alpha thresholds, 0.99 clamp, 1e-4 termination)
// from the equations, sharing no code with the renderer.
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/model/gaussian_model.h"

namespace mgsr::testing {

// The model's parameter blocks in double precision, for numeric differentiation.
struct GaussianModelD {
  int max_sh_degree = 3;
  std::vector<double> means, log_scales, quats, opacity_logits, sh, ref_sh, ref_opacity_logits,
      beta_logits;
  size_t size() const { return opacity_logits.size(); }
  int sh_coeffs() const { return (max_sh_degree + 1) * (max_sh_degree + 1); }
  explicit GaussianModelD(const GaussianModel& m)
      : max_sh_degree(m.max_sh_degree),
        means(m.means.begin(), m.means.end()),
        log_scales(m.log_scales.begin(), m.log_scales.end()),
        quats(m.quats.begin(), m.quats.end()),
        opacity_logits(m.opacity_logits.begin(), m.opacity_logits.end()),
        sh(m.sh.begin(), m.sh.end()),
        ref_sh(m.ref_sh.begin(), m.ref_sh.end()),
        ref_opacity_logits(m.ref_opacity_logits.begin(), m.ref_opacity_logits.end()),
        beta_logits(m.beta_logits.begin(), m.beta_logits.end()) {}
};

struct ReferenceGaussianRender {
  int width = 0, height = 0;
  std::vector<double> color, tran, ref;  // 3 x H x W planar
  std::vector<double> weight, depth, alpha;
};

template <typename Scalar>
inline void ReferenceShColor(int degree, const Scalar* sh, const Eigen::Vector3d& d,
                             double rgb[3]) {
  const double x = d.x(), y = d.y(), z = d.z();
  double b[16] = {0.28209479177387814};
  b[1] = -0.4886025119029199 * y;
  b[2] = 0.4886025119029199 * z;
  b[3] = -0.4886025119029199 * x;
  b[4] = 1.0925484305920792 * x * y;
  b[5] = -1.0925484305920792 * y * z;
  b[6] = 0.31539156525252005 * (2 * z * z - x * x - y * y);
  b[7] = -1.0925484305920792 * x * z;
  b[8] = 0.5462742152960396 * (x * x - y * y);
  b[9] = -0.5900435899266435 * y * (3 * x * x - y * y);
  b[10] = 2.890611442640554 * x * y * z;
  b[11] = -0.4570457994644658 * y * (4 * z * z - x * x - y * y);
  b[12] = 0.3731763325901154 * z * (2 * z * z - 3 * x * x - 3 * y * y);
  b[13] = -0.4570457994644658 * x * (4 * z * z - x * x - y * y);
  b[14] = 1.445305721320277 * z * (x * x - y * y);
  b[15] = -0.5900435899266435 * x * (x * x - 3 * y * y);
  const int n = (degree + 1) * (degree + 1);
  for (int c = 0; c < 3; ++c) {
    double v = 0.5;
    for (int k = 0; k < n; ++k) v += b[k] * sh[k * 3 + c];
    rgb[c] = std::max(0.0, v);
  }
}

// Works on GaussianModel (float) and on the double copy below.
template <typename Model>
inline ReferenceGaussianRender RenderGaussiansReference(
    const Model& m, const Camera& cam, int sh_degree, bool reflection, const double bg[3],
    const std::vector<double>* bg_image = nullptr) {
  struct Splat {
    double u, v, a, b, c, radius, z, o, ro, beta, ct[3], cr[3];
  };
  std::vector<Splat> splats;
  const int K = m.sh_coeffs();
  const double fx = cam.fx, fy = cam.fy;
  for (size_t i = 0; i < m.size(); ++i) {
    const Eigen::Vector3d mu(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
    const Eigen::Vector3d t = cam.R * mu + cam.t;
    if (!(t.z() > 0.2)) continue;
    Eigen::Quaterniond q(m.quats[4 * i], m.quats[4 * i + 1], m.quats[4 * i + 2],
                         m.quats[4 * i + 3]);
    q.normalize();
    const Eigen::Vector3d s(std::exp(m.log_scales[3 * i]), std::exp(m.log_scales[3 * i + 1]),
                            std::exp(m.log_scales[3 * i + 2]));
    const Eigen::Matrix3d Sigma =
        q.toRotationMatrix() * s.cwiseAbs2().asDiagonal() * q.toRotationMatrix().transpose();
    const double limx = 1.3 * 0.5 * cam.width / fx, limy = 1.3 * 0.5 * cam.height / fy;
    const double rx = std::clamp(t.x() / t.z(), -limx, limx),
                 ry = std::clamp(t.y() / t.z(), -limy, limy);
    Eigen::Matrix<double, 2, 3> J;
    J << fx / t.z(), 0, -fx * rx / t.z(), 0, fy / t.z(), -fy * ry / t.z();
    Eigen::Matrix2d cov = J * cam.R * Sigma * cam.R.transpose() * J.transpose();
    cov(0, 0) += 0.3;
    cov(1, 1) += 0.3;
    const double det = cov.determinant();
    if (!(det > 0)) continue;
    const double mid = 0.5 * (cov(0, 0) + cov(1, 1));
    Splat sp;
    // The renderer computes the radius in float; ceil() of a float and of a double agree
    // except within float rounding of an integer, which random scenes do not hit.
    sp.radius = std::ceil(3.0 * std::sqrt(mid + std::sqrt(std::max(0.1, mid * mid - det))));
    sp.u = fx * t.x() / t.z() + cam.cx;
    sp.v = fy * t.y() / t.z() + cam.cy;
    sp.a = cov(1, 1) / det;
    sp.b = -cov(0, 1) / det;
    sp.c = cov(0, 0) / det;
    sp.z = t.z();
    sp.o = 1 / (1 + std::exp(-static_cast<double>(m.opacity_logits[i])));
    sp.ro = 1 / (1 + std::exp(-static_cast<double>(m.ref_opacity_logits[i])));
    sp.beta = 1 / (1 + std::exp(-static_cast<double>(m.beta_logits[i])));
    const Eigen::Vector3d dir = (mu - cam.Center()).normalized();
    const int degree = std::min(sh_degree, m.max_sh_degree);
    ReferenceShColor(degree, &m.sh[i * K * 3], dir, sp.ct);
    ReferenceShColor(degree, &m.ref_sh[i * K * 3], dir, sp.cr);
    splats.push_back(sp);
  }
  std::stable_sort(splats.begin(), splats.end(),
                   [](const Splat& a, const Splat& b) { return a.z < b.z; });
  ReferenceGaussianRender r;
  r.width = cam.width;
  r.height = cam.height;
  const size_t np = static_cast<size_t>(cam.width) * cam.height;
  r.color.assign(3 * np, 0);
  r.tran.assign(3 * np, 0);
  r.ref.assign(3 * np, 0);
  r.weight.assign(np, 0);
  r.depth.assign(np, 0);
  r.alpha.assign(np, 0);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const double px = x + 0.5, py = y + 0.5;
      double T = 1, Tr = 1, Ct[3] = {0, 0, 0}, Cr[3] = {0, 0, 0}, W = 0, D = 0;
      bool done_t = false, done_r = !reflection;
      for (const Splat& s : splats) {
        if (done_t && done_r) break;
        const double dx = px - s.u, dy = py - s.v;
        if (std::abs(dx) > s.radius || std::abs(dy) > s.radius) continue;
        const double power = -0.5 * (s.a * dx * dx + s.c * dy * dy) - s.b * dx * dy;
        if (power > 0) continue;
        const double G = std::exp(power);
        if (!done_t) {
          const double a = std::min(0.99, s.o * G);
          if (a >= 1.0 / 255.0) {
            if (T * (1 - a) < 1e-4) {
              done_t = true;
            } else {
              for (int c = 0; c < 3; ++c) Ct[c] += s.ct[c] * a * T;
              W += s.beta * a * T;
              D += s.z * a * T;
              T *= 1 - a;
            }
          }
        }
        if (!done_r) {
          const double a = std::min(0.99, s.ro * G);
          if (a >= 1.0 / 255.0) {
            if (Tr * (1 - a) < 1e-4) {
              done_r = true;
            } else {
              for (int c = 0; c < 3; ++c) Cr[c] += s.cr[c] * a * Tr;
              Tr *= 1 - a;
            }
          }
        }
      }
      const size_t p = static_cast<size_t>(y) * cam.width + x;
      const double A = 1 - T;
      for (int c = 0; c < 3; ++c) {
        r.tran[c * np + p] = Ct[c] + T * (bg_image != nullptr ? (*bg_image)[c * np + p] : bg[c]);
        r.ref[c * np + p] = Cr[c];
        r.color[c * np + p] = r.tran[c * np + p] + W * Cr[c];
      }
      r.weight[p] = W;
      r.alpha[p] = A;
      r.depth[p] = A >= 1e-4 ? D / A : 0;
    }
  }
  return r;
}

}  // namespace mgsr::testing
