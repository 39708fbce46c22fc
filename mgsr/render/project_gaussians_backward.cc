// The backward of the 3DGS projection (ProjectGaussians, in project_gaussians.cc): per Gaussian,
// from the gradients of what the projection wrote to those of the model's parameters.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "mgsr/core/zero_fill.h"
#include "mgsr/model/activations.h"
#include "mgsr/render/prefetch_rows.h"
#include "mgsr/render/project_gaussians.h"
#include "mgsr/render/sh.h"

namespace mgsr {
namespace {

using Mat3 = Eigen::Matrix<float, 3, 3, Eigen::RowMajor>;
using Mat23 = Eigen::Matrix<float, 2, 3, Eigen::RowMajor>;

// Quantities shared by forward and backward for one Gaussian.
struct Geometry {
  Eigen::Vector3f t;  // view-space mean
  Mat3 Rq;            // rotation of the Gaussian
  Eigen::Vector3f s;  // scales
  Mat3 M;             // Rq * diag(s)
  Mat3 Sigma;         // M M^T
  float rx, ry;       // clamped t.x / t.z, t.y / t.z
  bool clamped_x, clamped_y;
  Mat23 J, T;  // T = J * R_cam
  Eigen::Matrix2f cov;
};

// Kept out of line, as it was when the forward shared it: inlined here, GCC would fuse the
// multiply-adds around it differently and the gradients would change in their last bits.
__attribute__((noinline)) void ComputeGeometry(const GaussianModel& m, size_t i, const Mat3& Rc,
                                               const Eigen::Vector3f& tc, const Camera& cam,
                                               Geometry* g) {
  const Eigen::Vector3f mean(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
  g->t = Rc * mean + tc;
  float q_unit[4];
  QuaternionToRotation(&m.quats[4 * i], g->Rq.data(), q_unit);
  g->s = Eigen::Vector3f(std::exp(m.log_scales[3 * i]), std::exp(m.log_scales[3 * i + 1]),
                         std::exp(m.log_scales[3 * i + 2]));
  g->M = g->Rq * g->s.asDiagonal();
  g->Sigma = g->M * g->M.transpose();
  const float z = g->t.z();
  const float lim_x = kFovClamp * 0.5f * cam.width / static_cast<float>(cam.fx);
  const float lim_y = kFovClamp * 0.5f * cam.height / static_cast<float>(cam.fy);
  const float ux = g->t.x() / z, uy = g->t.y() / z;
  g->clamped_x = ux < -lim_x || ux > lim_x;
  g->clamped_y = uy < -lim_y || uy > lim_y;
  g->rx = std::clamp(ux, -lim_x, lim_x);
  g->ry = std::clamp(uy, -lim_y, lim_y);
  const float fx = static_cast<float>(cam.fx), fy = static_cast<float>(cam.fy);
  g->J << fx / z, 0, -fx * g->rx / z, 0, fy / z, -fy * g->ry / z;
  g->T = g->J * Rc;
  g->cov = g->T * g->Sigma * g->T.transpose();
  g->cov(0, 0) += kScreenDilation;
  g->cov(1, 1) += kScreenDilation;
}

}  // namespace

void ProjectedGaussiansGrad::ResizeAndZero(size_t n) {
  for (auto* v : {&mean2d}) ZeroFill(2 * n, v);
  for (auto* v : {&conic, &color_t, &color_r}) ZeroFill(3 * n, v);
  for (auto* v : {&depth, &opacity, &ref_opacity, &beta}) ZeroFill(n, v);
}

void GaussianGradients::ResizeAndZero(const GaussianModel& model) {
  ResizeForBackward(model);
  for (auto* v : {&params.sh, &params.ref_sh}) ZeroFill(v->size(), v);
}

void GaussianGradients::ResizeForBackward(const GaussianModel& model) {
  params.max_sh_degree = model.max_sh_degree;
  const size_t n = model.size(), k3 = 3 * static_cast<size_t>(params.sh_coeffs());
  for (auto* v : {&params.means, &params.log_scales}) ZeroFill(3 * n, v);
  ZeroFill(4 * n, &params.quats);
  for (auto* v : {&params.sh, &params.ref_sh}) v->resize(k3 * n);
  for (auto* v : {&params.opacity_logits, &params.ref_opacity_logits, &params.beta_logits})
    ZeroFill(n, v);
  ZeroFill(2 * n, &mean2d);
}

void ScreenGradientNorms(const std::vector<float>& mean2d, int width, int height,
                         std::vector<float>* norms) {
  const size_t n = mean2d.size() / 2;
  norms->resize(n);
  for (size_t i = 0; i < n; ++i) {
    const float gx = mean2d[2 * i] * 0.5f * width, gy = mean2d[2 * i + 1] * 0.5f * height;
    (*norms)[i] = std::sqrt(gx * gx + gy * gy);
  }
}

void ProjectGaussiansBackward(const GaussianModel& m, const Camera& cam, int sh_degree,
                              bool reflection, const ProjectedGaussians& p,
                              const ProjectedGaussiansGrad& d, GaussianGradients* grads) {
  const int n = static_cast<int>(m.size());
  const Mat3 Rc = cam.R.cast<float>();
  const Eigen::Vector3f tc = cam.t.cast<float>();
  const Eigen::Vector3f center = cam.Center().cast<float>();
  const float fx = static_cast<float>(cam.fx), fy = static_cast<float>(cam.fy);
  const int K = m.sh_coeffs();
  const int degree = std::min(sh_degree, m.max_sh_degree);
  const int n_coeffs = (degree + 1) * (degree + 1);
  GaussianModel& G = grads->params;
  const size_t row = static_cast<size_t>(K) * 3;  // SH floats per Gaussian
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (i + kPrefetchAhead < n) {  // the coefficients read and the gradient rows written
      const size_t ahead = row * (i + kPrefetchAhead);
      PrefetchRow(&m.sh[ahead], 3 * n_coeffs);
      if (reflection) PrefetchRow(&m.ref_sh[ahead], 3 * n_coeffs);
      PrefetchRow(&G.sh[ahead], row);
      PrefetchRow(&G.ref_sh[ahead], row);
    }
    float* const d_sh = &G.sh[row * i];
    float* const d_ref_sh = &G.ref_sh[row * i];
    if (p.radius[i] <= 0) {  // not drawn: its SH rows are written zero, the rest stays zero
      std::fill(d_sh, d_sh + row, 0.0f);
      std::fill(d_ref_sh, d_ref_sh + row, 0.0f);
      continue;
    }
    grads->mean2d[2 * i] += d.mean2d[2 * i];
    grads->mean2d[2 * i + 1] += d.mean2d[2 * i + 1];
    // Activations.
    G.opacity_logits[i] += d.opacity[i] * SigmoidGradFromValue(p.opacity[i]);
    if (reflection) {
      G.ref_opacity_logits[i] += d.ref_opacity[i] * SigmoidGradFromValue(p.ref_opacity[i]);
      G.beta_logits[i] += d.beta[i] * SigmoidGradFromValue(p.beta[i]);
    }
    // Colours -> SH coefficients and the view direction.
    Eigen::Vector3f d_mean = Eigen::Vector3f::Zero();
    float sum_dir[3] = {0, 0, 0}, d_v[3];  // d/d dir from both colours
    float basis[kMaxShCoeffs], dbasis[kMaxShCoeffs][3];
    ShBasisWithGradient(degree, &p.view_dir[3 * i], basis, dbasis);
    // The coefficients above the current degree get zero.
    WriteShColorBackwardFromBasis(n_coeffs, basis, dbasis, &m.sh[row * i], &p.clamp_t[3 * i],
                                  &d.color_t[3 * i], d_sh, sum_dir);
    std::fill(d_sh + 3 * n_coeffs, d_sh + row, 0.0f);
    if (reflection) {
      WriteShColorBackwardFromBasis(n_coeffs, basis, dbasis, &m.ref_sh[row * i], &p.clamp_r[3 * i],
                                    &d.color_r[3 * i], d_ref_sh, sum_dir);
      std::fill(d_ref_sh + 3 * n_coeffs, d_ref_sh + row, 0.0f);
    } else {
      std::fill(d_ref_sh, d_ref_sh + row, 0.0f);
    }
    const Eigen::Vector3f mean(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
    const Eigen::Vector3f v = mean - center;
    NormalizeBackward(v.data(), sum_dir, d_v);
    d_mean += Eigen::Vector3f(d_v[0], d_v[1], d_v[2]);

    Geometry g;
    ComputeGeometry(m, i, Rc, tc, cam, &g);
    const float z = g.t.z(), tx = g.t.x(), ty = g.t.y();
    // conic -> screen covariance: dCov = -Q dQ Q with the symmetric dQ (b appears twice).
    Eigen::Matrix2f Q;
    Q << p.conic[3 * i], p.conic[3 * i + 1], p.conic[3 * i + 1], p.conic[3 * i + 2];
    Eigen::Matrix2f dQ;
    dQ << d.conic[3 * i], 0.5f * d.conic[3 * i + 1], 0.5f * d.conic[3 * i + 1], d.conic[3 * i + 2];
    const Eigen::Matrix2f dCov = -Q * dQ * Q;
    // Cov = T Sigma T^T (+ dilation): dSigma = T^T dCov T, dT = 2 dCov T Sigma.
    const Mat3 dSigma = g.T.transpose() * dCov * g.T;
    const Mat23 dT = 2.0f * dCov * g.T * g.Sigma;
    const Mat23 dJ = dT * Rc.transpose();
    // J entries -> view-space mean (the clamped ratio carries no gradient).
    const float mx = g.clamped_x ? 0.0f : 1.0f, my = g.clamped_y ? 0.0f : 1.0f;
    Eigen::Vector3f d_t = Eigen::Vector3f::Zero();
    d_t.x() += dJ(0, 2) * (-fx * mx / (z * z));
    d_t.y() += dJ(1, 2) * (-fy * my / (z * z));
    d_t.z() += dJ(0, 0) * (-fx / (z * z)) + dJ(1, 1) * (-fy / (z * z)) +
               dJ(0, 2) * (fx * g.rx / (z * z) + fx * mx * tx / (z * z * z)) +
               dJ(1, 2) * (fy * g.ry / (z * z) + fy * my * ty / (z * z * z));
    // Screen mean and depth.
    const float du = d.mean2d[2 * i], dv = d.mean2d[2 * i + 1];
    d_t.x() += du * fx / z;
    d_t.y() += dv * fy / z;
    d_t.z() += -du * fx * tx / (z * z) - dv * fy * ty / (z * z) + d.depth[i];
    d_mean += Rc.transpose() * d_t;
    for (int k = 0; k < 3; ++k) G.means[3 * i + k] += d_mean[k];
    // Sigma = M M^T, M = Rq diag(s).
    const Mat3 dM = 2.0f * dSigma * g.M;
    Mat3 dRq;
    for (int k = 0; k < 3; ++k) {
      const float ds = g.Rq.col(k).dot(dM.col(k));
      G.log_scales[3 * i + k] += ds * g.s[k];
      dRq.col(k) = g.s[k] * dM.col(k);
    }
    float dq[4];
    QuaternionToRotationBackward(&m.quats[4 * i], dRq.data(), dq);
    for (int k = 0; k < 4; ++k) G.quats[4 * i + k] += dq[k];
  }
}

}  // namespace mgsr
