#include "mgsr/render/project_gaussians.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "mgsr/model/activations.h"
#include "mgsr/render/prefetch_rows.h"
#include "mgsr/render/projection_lanes.h"
#include "mgsr/render/sh.h"

namespace mgsr {

using projection_lanes::DotPackedOrder;
using projection_lanes::DotScalarOrder;
using projection_lanes::FusedMultiplyAdd;
using projection_lanes::kLanes;
using projection_lanes::MaxValue;

bool AlphaExtent(float cov_xx, float cov_yy, float opacity, float radius, float* ex, float* ey) {
  if (!(opacity > kMinBlendAlpha)) return false;
  // alpha = o exp(-d^T cov^-1 d / 2) >= 1/255 inside the ellipse d^T cov^-1 d <= k, whose
  // bounding box has half-widths sqrt(k cov_xx) and sqrt(k cov_yy). The 1% and 0.01 px margin
  // cover float rounding in the pixel loops' exponent, so no pixel they would blend falls outside.
  const float k = 2.0f * std::log(opacity / kMinBlendAlpha);
  *ex = std::min(radius, FusedMultiplyAdd(std::sqrt(k * cov_xx), 1.01f, 0.01f));
  *ey = std::min(radius, FusedMultiplyAdd(std::sqrt(k * cov_yy), 1.01f, 0.01f));
  return true;
}

void ProjectedGaussians::Resize(size_t n) {
  mean2d.resize(2 * n);
  conic.resize(3 * n);
  depth.resize(n);
  radius.resize(n);
  extent.resize(2 * n);
  min_power.resize(n);
  rects.resize(n);
  opacity.resize(n);
  ref_opacity.resize(n);
  beta.resize(n);
  color_t.resize(3 * n);
  color_r.resize(3 * n);
  clamp_t.resize(3 * n);
  clamp_r.resize(3 * n);
  view_dir.resize(3 * n);
}

namespace {

using Mat3 = Eigen::Matrix<float, 3, 3, Eigen::RowMajor>;

// The forward runs over blocks of kLanes Gaussians (see projection_lanes.h): a scalar pass gathers
// the parameters and takes the scales' exp, lane loops GCC vectorises compute the geometry (the
// view-space mean, the covariance and its EWA screen image, the conic, the radius, the screen mean
// and the view direction), and a scalar pass writes what is kept, with the opacities, the alpha
// box and the SH colours. This file is built without contraction (-ffp-contract=off): every fused
// multiply-add is the one spelled out, as the per-Gaussian Eigen code had them; every output was
// the same to the bit as that code's on the benchmark scene and on scenes with zero quaternions,
// Gaussians behind and beside the camera, huge and tiny scales, all four SH degrees.
struct GaussianLanes {
  // Inputs (pass 1).
  float q[4][kLanes], mean[3][kLanes], s[3][kLanes];
  // Results (pass 2).
  float R[9][kLanes], t[3][kLanes], cov[3][kLanes];  // cov: a, b, c
  float det[kLanes], radius[kLanes], u[kLanes], v[kLanes], dir[3][kLanes];
  int ok[kLanes];  // passed every test before the tile rectangle's
};

}  // namespace

void ProjectGaussians(const GaussianModel& m, const Camera& cam, int sh_degree, bool reflection,
                      ProjectedGaussians* out) {
  const int n = static_cast<int>(m.size());
  out->Resize(n);
  const Mat3 Rc = cam.R.cast<float>();
  const Eigen::Vector3f tc = cam.t.cast<float>();
  const Eigen::Vector3f center = cam.Center().cast<float>();
  const int tiles_x = (cam.width + kTileSize - 1) / kTileSize;
  const int tiles_y = (cam.height + kTileSize - 1) / kTileSize;
  const int K = m.sh_coeffs();
  const int degree = std::min(sh_degree, m.max_sh_degree);
  const int n_coeffs = (degree + 1) * (degree + 1);
  const float fx = static_cast<float>(cam.fx), fy = static_cast<float>(cam.fy);
  const float cx = static_cast<float>(cam.cx), cy = static_cast<float>(cam.cy);
  // The clamp of the Jacobian's x/z and y/z to 1.3 x the half field of view.
  const float lim_x = kFovClamp * 0.5f * cam.width / fx;
  const float lim_y = kFovClamp * 0.5f * cam.height / fy;
  const int blocks = (n + kLanes - 1) / kLanes;
#pragma omp parallel for schedule(static)
  for (int b = 0; b < blocks; ++b) {
    GaussianLanes L;
    const int base = b * kLanes, count = std::min(kLanes, n - base);
    // Pass 1: gather, and the scales' exp. (Lanes past the end repeat the first Gaussian.)
    for (int l = 0; l < kLanes; ++l) {
      const size_t i = base + (l < count ? l : 0);
      for (int k = 0; k < 4; ++k) L.q[k][l] = m.quats[4 * i + k];
      for (int k = 0; k < 3; ++k) {
        L.mean[k][l] = m.means[3 * i + k];
        L.s[k][l] = std::exp(m.log_scales[3 * i + k]);
      }
    }
    // Pass 2: the geometry of every lane.
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the rotation
      projection_lanes::LaneRotation(L.q[0][l], L.q[1][l], L.q[2][l], L.q[3][l], L.R, l);
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the view-space mean, the screen mean and the direction
      const float m0 = L.mean[0][l], m1 = L.mean[1][l], m2 = L.mean[2][l];
      float t[3];
#pragma GCC unroll 3
      for (int r = 0; r < 3; ++r)
        t[r] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), m0, m1, m2) + tc[r];
#pragma GCC unroll 3
      for (int r = 0; r < 3; ++r) L.t[r][l] = t[r];
      L.u[l] = fx * t[0] / t[2] + cx;
      L.v[l] = fy * t[1] / t[2] + cy;
      // (mean - camera centre).normalized()
      const float d0 = m0 - center[0], d1 = m1 - center[1], d2 = m2 - center[2];
      const float sq = DotScalarOrder(d0, d1, d2, d0, d1, d2);
      const float len = std::sqrt(sq);
      const float u0 = d0 / len, u1 = d1 / len, u2 = d2 / len;
      L.dir[0][l] = sq > 0.0f ? u0 : d0;
      L.dir[1][l] = sq > 0.0f ? u1 : d1;
      L.dir[2][l] = sq > 0.0f ? u2 : d2;
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // cov = T Sigma T^T + dilation, T = J R_c
      // Sigma = M M^T, M = R diag(s) (symmetric: each entry once).
      float M[3][3];
#pragma GCC unroll 9
      for (int k = 0; k < 9; ++k) M[k / 3][k % 3] = L.R[k][l] * L.s[k % 3][l];
      float S[3][3];
      S[0][0] = DotScalarOrder(M[0][0], M[0][1], M[0][2], M[0][0], M[0][1], M[0][2]);
      S[0][1] = S[1][0] = DotScalarOrder(M[0][0], M[0][1], M[0][2], M[1][0], M[1][1], M[1][2]);
      S[0][2] = S[2][0] = DotScalarOrder(M[0][0], M[0][1], M[0][2], M[2][0], M[2][1], M[2][2]);
      S[1][1] = DotScalarOrder(M[1][0], M[1][1], M[1][2], M[1][0], M[1][1], M[1][2]);
      S[1][2] = S[2][1] = DotScalarOrder(M[1][0], M[1][1], M[1][2], M[2][0], M[2][1], M[2][2]);
      S[2][2] = DotScalarOrder(M[2][0], M[2][1], M[2][2], M[2][0], M[2][1], M[2][2]);
      // The Jacobian of the perspective division at the clamped x/z, y/z.
      const float z = L.t[2][l];
      const float ux = L.t[0][l] / z, uy = L.t[1][l] / z;
      const float rx = ux < -lim_x ? -lim_x : (lim_x < ux ? lim_x : ux);
      const float ry = uy < -lim_y ? -lim_y : (lim_y < uy ? lim_y : uy);
      const float j00 = fx / z, j02 = -fx * rx / z, j11 = fy / z, j12 = -fy * ry / z;
      float T[2][3];
#pragma GCC unroll 3
      for (int c = 0; c < 3; ++c) {
        // (Eigen's first row: its zero product and the third fused, the first added apart.)
        T[0][c] = j00 * Rc(0, c) + FusedMultiplyAdd(j02, Rc(2, c), 0.0f * Rc(1, c));
        T[1][c] = DotScalarOrder(0.0f, j11, j12, Rc(0, c), Rc(1, c), Rc(2, c));
      }
      float TS[2][3];
#pragma GCC unroll 6
      for (int k = 0; k < 6; ++k) {
        const int r = k / 3, c = k % 3;
        TS[r][c] = DotPackedOrder(T[r][0], T[r][1], T[r][2], S[0][c], S[1][c], S[2][c]);
      }
      const float a =
          DotPackedOrder(TS[0][0], TS[0][1], TS[0][2], T[0][0], T[0][1], T[0][2]) + kScreenDilation;
      const float bb = DotPackedOrder(TS[0][0], TS[0][1], TS[0][2], T[1][0], T[1][1], T[1][2]);
      const float c =
          DotPackedOrder(TS[1][0], TS[1][1], TS[1][2], T[1][0], T[1][1], T[1][2]) + kScreenDilation;
      L.cov[0][l] = a;
      L.cov[1][l] = bb;
      L.cov[2][l] = c;
      const float det = FusedMultiplyAdd(a, c, -(bb * bb));
      L.det[l] = det;
      const float mid = 0.5f * (a + c);
      const float lambda = mid + std::sqrt(MaxValue(0.1f, FusedMultiplyAdd(mid, mid, -det)));
      L.radius[l] = 3.0f * std::sqrt(lambda);  // before its ceil, below
      L.ok[l] = (z > kNearPlane) & (det > 0) & std::isfinite(det) & std::isfinite(L.u[l]) &
                std::isfinite(L.v[l]);
    }
    for (int l = 0; l < kLanes; ++l) L.radius[l] = std::ceil(L.radius[l]);  // (not vectorised)
    // Pass 3: write out, with the opacities, the alpha box and the SH colours.
    for (int l = 0; l < count; ++l) {
      const int i = base + l;
      if (i + kPrefetchAhead < n) {  // the coefficients the colours read
        const size_t ahead = static_cast<size_t>(i + kPrefetchAhead) * K * 3;
        PrefetchRow(&m.sh[ahead], 3 * n_coeffs);
        if (reflection) PrefetchRow(&m.ref_sh[ahead], 3 * n_coeffs);
      }
      out->depth[i] = L.t[2][l];
      out->radius[i] = 0;
      out->rects[i] = TileRect();
      out->extent[2 * i] = out->extent[2 * i + 1] = 0;
      out->min_power[i] = 0;
      const float radius = L.radius[l], u = L.u[l], v = L.v[l];
      // Visible (radius > 0, what density control reads) when the 3-sigma square meets the image.
      if (!L.ok[l] || TileRectFromBox(u, v, radius, radius, tiles_x, tiles_y).empty()) continue;
      out->radius[i] = radius;
      out->opacity[i] = Sigmoid(m.opacity_logits[i]);
      if (reflection) out->ref_opacity[i] = Sigmoid(m.ref_opacity_logits[i]);
      // Binned where it can blend: a primitive too faint for 1/255 anywhere gets no tiles.
      const float o = reflection ? std::max(out->opacity[i], out->ref_opacity[i]) : out->opacity[i];
      const float a = L.cov[0][l], bb = L.cov[1][l], c = L.cov[2][l], det = L.det[l];
      float ex = 0, ey = 0;
      if (AlphaExtent(a, c, o, radius, &ex, &ey)) {
        out->rects[i] = TileRectFromBox(u, v, ex, ey, tiles_x, tiles_y);
        out->min_power[i] = std::log(kMinBlendAlpha / o);
      }
      out->extent[2 * i] = ex;
      out->extent[2 * i + 1] = ey;
      out->mean2d[2 * i] = u;
      out->mean2d[2 * i + 1] = v;
      out->conic[3 * i] = c / det;
      out->conic[3 * i + 1] = -bb / det;
      out->conic[3 * i + 2] = a / det;
      for (int k = 0; k < 3; ++k) out->view_dir[3 * i + k] = L.dir[k][l];
      float basis[kMaxShCoeffs];  // shared by the transmitted and the reflected colour
      ShBasis(degree, &out->view_dir[3 * i], basis);
      EvalShColorFromBasis(n_coeffs, basis, &m.sh[static_cast<size_t>(i) * K * 3],
                           &out->color_t[3 * i], &out->clamp_t[3 * i]);
      if (reflection) {
        out->beta[i] = Sigmoid(m.beta_logits[i]);
        EvalShColorFromBasis(n_coeffs, basis, &m.ref_sh[static_cast<size_t>(i) * K * 3],
                             &out->color_r[3 * i], &out->clamp_r[3 * i]);
      }
    }
  }
}

}  // namespace mgsr
