// The backward of the 2DGS projection (ProjectSurfels, in project_surfels.cc): per surfel, from
// the gradients of what the projection wrote to those of the model's parameters.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "mgsr/core/zero_fill.h"
#include "mgsr/model/activations.h"
#include "mgsr/render/prefetch_rows.h"
#include "mgsr/render/project_surfels.h"
#include "mgsr/render/sh.h"

namespace mgsr {
namespace {

using Mat3 = Eigen::Matrix<float, 3, 3, Eigen::RowMajor>;

struct SurfelGeometry {
  Mat3 R;  // columns t_u, t_v, t_w
  float su, sv;
  Eigen::Vector3f p;  // centre (world)
  Mat3 A;             // R_c [s_u t_u, s_v t_v, p] + t_c e3^T
  Mat3 M;             // K A, rows T_u, T_v, T_w
};

Mat3 Intrinsics(const Camera& cam) {
  Mat3 K;
  K << static_cast<float>(cam.fx), 0, static_cast<float>(cam.cx), 0, static_cast<float>(cam.fy),
      static_cast<float>(cam.cy), 0, 0, 1;
  return K;
}

// Kept out of line, as it was when the forward shared it: inlined here, GCC fuses the
// multiply-adds around it differently and the gradients would change in their last bits.
__attribute__((noinline)) void ComputeGeometry(const SurfelModel& m, size_t i, const Mat3& Rc,
                                               const Eigen::Vector3f& tc, const Mat3& K,
                                               SurfelGeometry* g) {
  float q_unit[4];
  QuaternionToRotation(&m.quats[4 * i], g->R.data(), q_unit);
  g->su = std::exp(m.log_scales[2 * i]);
  g->sv = std::exp(m.log_scales[2 * i + 1]);
  g->p = Eigen::Vector3f(m.means[3 * i], m.means[3 * i + 1], m.means[3 * i + 2]);
  g->A.col(0) = Rc * (g->su * g->R.col(0));
  g->A.col(1) = Rc * (g->sv * g->R.col(1));
  g->A.col(2) = Rc * g->p + tc;
  g->M = K * g->A;
}

}  // namespace

void ProjectedSurfelsGrad::ResizeAndZero(size_t n) {
  ZeroFill(9 * n, &M);
  ZeroFill(2 * n, &center);
  ZeroFill(3 * n, &normal);
  ZeroFill(n, &opacity);
  ZeroFill(3 * n, &color);
}

void SurfelGradients::ResizeAndZero(const SurfelModel& model) {
  ResizeForBackward(model);
  ZeroFill(params.sh.size(), &params.sh);
}

void SurfelGradients::ResizeForBackward(const SurfelModel& model) {
  params.max_sh_degree = model.max_sh_degree;
  const size_t n = model.size();
  ZeroFill(3 * n, &params.means);
  ZeroFill(2 * n, &params.log_scales);
  ZeroFill(4 * n, &params.quats);
  ZeroFill(n, &params.opacity_logits);
  params.sh.resize(3 * static_cast<size_t>(params.sh_coeffs()) * n);
  ZeroFill(2 * n, &mean2d);
}

void ProjectSurfelsBackward(const SurfelModel& m, const Camera& cam, int sh_degree,
                            const ProjectedSurfels& p, const ProjectedSurfelsGrad& d,
                            SurfelGradients* grads) {
  const int n = static_cast<int>(m.size());
  const Mat3 Rc = cam.R.cast<float>();
  const Eigen::Vector3f tc = cam.t.cast<float>();
  const Eigen::Vector3f center = cam.Center().cast<float>();
  const Mat3 K = Intrinsics(cam);
  const int Kc = m.sh_coeffs();
  const int degree = std::min(sh_degree, m.max_sh_degree);
  SurfelModel& G = grads->params;
  const size_t row = static_cast<size_t>(Kc) * 3;  // SH floats per surfel
  const int n_coeffs = (degree + 1) * (degree + 1);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (i + kPrefetchAhead < n) {  // the coefficients read and the gradient row written
      PrefetchRow(&m.sh[row * (i + kPrefetchAhead)], 3 * n_coeffs);
      PrefetchRow(&G.sh[row * (i + kPrefetchAhead)], row);
    }
    float* const d_sh = &G.sh[row * i];
    if (p.radius[i] <= 0) {  // not drawn: its SH row is written zero, the rest stays zero
      std::fill(d_sh, d_sh + row, 0.0f);
      continue;
    }
    SurfelGeometry g;
    ComputeGeometry(m, i, Rc, tc, K, &g);
    G.opacity_logits[i] += d.opacity[i] * SigmoidGradFromValue(p.opacity[i]);
    // Colour -> SH and the view direction.
    // (The coefficients above the current degree get zero.)
    float d_dir[3] = {0, 0, 0}, d_v[3];
    float basis[kMaxShCoeffs], dbasis[kMaxShCoeffs][3];
    ShBasisWithGradient(degree, &p.view_dir[3 * i], basis, dbasis);
    WriteShColorBackwardFromBasis(n_coeffs, basis, dbasis, &m.sh[row * i], &p.clamp[3 * i],
                                  &d.color[3 * i], d_sh, d_dir);
    std::fill(d_sh + 3 * n_coeffs, d_sh + row, 0.0f);
    const Eigen::Vector3f v = g.p - center;
    NormalizeBackward(v.data(), d_dir, d_v);
    Eigen::Vector3f d_p(d_v[0], d_v[1], d_v[2]);
    // d/dM from the rasterizer, plus the screen centre m = (f.(T_u o T_w), f.(T_v o T_w)).
    // Undo the centring T_u' = T_u - m_x T_w, T_v' = T_v - m_y T_w (m held as its own input).
    Mat3 dM;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) dM(r, c) = d.M[9 * i + 3 * r + c];
    }
    const float cx = p.center[2 * i], cy = p.center[2 * i + 1];
    const Eigen::Vector3f dTu_c = dM.row(0), dTv_c = dM.row(1);
    const Eigen::Vector3f Tw_row = g.M.row(2);
    dM.row(2) -= (cx * dTu_c + cy * dTv_c).transpose();
    const float dmx = d.center[2 * i] - Tw_row.dot(dTu_c),
                dmy = d.center[2 * i + 1] - Tw_row.dot(dTv_c);
    if (dmx != 0.0f || dmy != 0.0f) {
      const Eigen::Vector3f Tu = g.M.row(0), Tv = g.M.row(1), Tw = g.M.row(2);
      const Eigen::Vector3f t(kSurfelCutoff2, kSurfelCutoff2, -1.0f);
      const float dd = t.dot(Tw.cwiseProduct(Tw));
      const Eigen::Vector3f f = t / dd;
      const float mx = f.dot(Tu.cwiseProduct(Tw)), my = f.dot(Tv.cwiseProduct(Tw));
      dM.row(0) += dmx * f.cwiseProduct(Tw).transpose();
      dM.row(1) += dmy * f.cwiseProduct(Tw).transpose();
      // d m / d T_w through the numerators and through d = t . (T_w o T_w).
      const Eigen::Vector3f dTw = dmx * (f.cwiseProduct(Tu) - 2.0f * mx * f.cwiseProduct(Tw)) +
                                  dmy * (f.cwiseProduct(Tv) - 2.0f * my * f.cwiseProduct(Tw));
      dM.row(2) += dTw.transpose();
    }
    // Densification statistic (reference 3.8(5)): the centre's x_num / y_num gradients scaled by
    // the depth, in pixels.
    grads->mean2d[2 * i] = dM(0, 2) * g.M(2, 2);
    grads->mean2d[2 * i + 1] = dM(1, 2) * g.M(2, 2);
    // M = K A: dA = K^T dM; A's columns are R_c s_u t_u, R_c s_v t_v, R_c p + t_c.
    const Mat3 dA = K.transpose() * dM;
    Mat3 dR = Mat3::Zero();
    const Eigen::Vector3f du = Rc.transpose() * dA.col(0), dv = Rc.transpose() * dA.col(1);
    G.log_scales[2 * i] += g.R.col(0).dot(du) * g.su;
    G.log_scales[2 * i + 1] += g.R.col(1).dot(dv) * g.sv;
    dR.col(0) = g.su * du;
    dR.col(1) = g.sv * dv;
    d_p += Rc.transpose() * dA.col(2);
    // Normal: n = sign R_c t_w.
    const Eigen::Vector3f dn(d.normal[3 * i], d.normal[3 * i + 1], d.normal[3 * i + 2]);
    dR.col(2) = p.normal_sign[i] * (Rc.transpose() * dn);
    float dq[4];
    QuaternionToRotationBackward(&m.quats[4 * i], dR.data(), dq);
    for (int k = 0; k < 4; ++k) G.quats[4 * i + k] += dq[k];
    for (int k = 0; k < 3; ++k) G.means[3 * i + k] += d_p[k];
  }
}

}  // namespace mgsr
