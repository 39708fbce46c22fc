#include "mgsr/render/project_gaussians.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "mgsr/core/zero_fill.h"
#include "mgsr/model/activations.h"
#include "mgsr/render/prefetch_rows.h"
#include "mgsr/render/projection_lanes.h"
#include "mgsr/render/sh.h"

namespace mgsr {

using projection_lanes::CameraLanes;
using projection_lanes::DotPackedOrder;
using projection_lanes::DotScalarOrder;
using projection_lanes::FusedMultiplyAdd;
using projection_lanes::kLanes;
using projection_lanes::LaneNormalizeBackward;
using projection_lanes::LaneRotationBackward;
using projection_lanes::MaxValue;
using projection_lanes::SigmoidGradient;

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
  shapes.resize(n);
  opacity.resize(n);
  ref_opacity.resize(n);
  beta.resize(n);
  color_t.resize(3 * n);
  color_r.resize(3 * n);
  clamp_t.resize(3 * n);
  clamp_r.resize(3 * n);
  view_dir.resize(3 * n);
}

void ProjectedGaussiansGrad::Resize(size_t n) {
  mean2d.resize(2 * n);
  for (auto* v : {&conic, &color_t, &color_r}) v->resize(3 * n);
  for (auto* v : {&depth, &opacity, &ref_opacity, &beta}) v->resize(n);
}

void ProjectedGaussiansGrad::ResizeAndZero(size_t n) {
  for (auto* v : {&mean2d}) ZeroFill(2 * n, v);
  for (auto* v : {&conic, &color_t, &color_r}) ZeroFill(3 * n, v);
  for (auto* v : {&depth, &opacity, &ref_opacity, &beta}) ZeroFill(n, v);
}

void GaussianGradients::ResizeAndZero(const GaussianModel& model) {
  ResizeForBackward(model);
  for (ParamBlock& b : params.Blocks()) ZeroFill(b.data->size(), b.data);
  ZeroFill(mean2d.size(), &mean2d);
}

void GaussianGradients::ResizeForBackward(const GaussianModel& model) {
  params.max_sh_degree = model.max_sh_degree;
  const size_t n = model.size(), k3 = 3 * static_cast<size_t>(params.sh_coeffs());
  for (auto* v : {&params.means, &params.log_scales}) v->resize(3 * n);
  params.quats.resize(4 * n);
  for (auto* v : {&params.sh, &params.ref_sh}) v->resize(k3 * n);
  for (auto* v : {&params.opacity_logits, &params.ref_opacity_logits, &params.beta_logits})
    v->resize(n);
  mean2d.resize(2 * n);
}

void ScreenGradientNorms(const std::vector<float>& mean2d, int width, int height,
                         std::vector<float>* norms) {
  const size_t n = mean2d.size() / 2;
  norms->resize(n);
  for (size_t i = 0; i < n; ++i) {
    const float gx = mean2d[2 * i] * 0.5f * width, gy = mean2d[2 * i + 1] * 0.5f * height;
    (*norms)[i] = std::sqrt(FusedMultiplyAdd(gx, gx, gy * gy));
  }
}

namespace {

using Mat3 = Eigen::Matrix<float, 3, 3, Eigen::RowMajor>;

// Both passes run over blocks of kLanes Gaussians (see projection_lanes.h): scalar passes gather
// and take the library calls and the SH colours (a row of coefficients per Gaussian), lane loops
// GCC vectorises take the geometry and its chain rule, and a scalar pass writes out. The
// activations and the SH colours run in loops of their own (the forward's colours after the
// blocks, everything else before them): a loop over some thirty per-Gaussian arrays follows more
// streams than the hardware prefetcher does, and its loads waited on memory. This file is
// built without contraction (-ffp-contract=off): every fused multiply-add is the one spelled out,
// as GCC had fused the per-Gaussian Eigen code before it; every output and gradient was the same
// to the bit as that code's on the benchmark scene and on scenes with zero quaternions, Gaussians
// behind and beside the camera, huge and tiny scales, all four SH degrees, with and without
// reflection.

// A block's Gaussians and their geometry, as both passes need them: the parameters (gathered by
// GatherGaussians) and, from GaussianGeometryLanes, the rotation R (row-major), the view-space
// mean t, M = R diag(s), Sigma = M M^T (S), the clamped x/z and y/z with their clamp flags and
// T = J R_c (J: the Jacobian of the perspective division).
struct GaussianGeometry {
  float q[4][kLanes], mean[3][kLanes], s[3][kLanes];
  float R[9][kLanes], t[3][kLanes], M[9][kLanes], S[9][kLanes], T[6][kLanes];
  float rx[kLanes], ry[kLanes];
  int clamped_x[kLanes], clamped_y[kLanes];
};

// Lanes past the end repeat the block's first Gaussian.
void GatherGaussians(const GaussianModel& m, int base, int count, GaussianGeometry* g) {
  for (int l = 0; l < kLanes; ++l) {
    const size_t i = base + (l < count ? l : 0);
    for (int k = 0; k < 4; ++k) g->q[k][l] = m.quats[4 * i + k];
    for (int k = 0; k < 3; ++k) {
      g->mean[k][l] = m.means[3 * i + k];
      g->s[k][l] = std::exp(m.log_scales[3 * i + k]);
    }
  }
}

// The clamp of the Jacobian's x/z and y/z to 1.3 x the half field of view.
float FovLimit(int size, double focal) {
  return kFovClamp * 0.5f * size / static_cast<float>(focal);
}

void GaussianGeometryLanes(const CameraLanes& c, float lim_x, float lim_y, GaussianGeometry* g) {
  const Mat3& Rc = c.Rc;
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {  // the rotation
    projection_lanes::LaneRotation(g->q[0][l], g->q[1][l], g->q[2][l], g->q[3][l], g->R, l);
  }
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {  // the view-space mean
    const float m0 = g->mean[0][l], m1 = g->mean[1][l], m2 = g->mean[2][l];
#pragma GCC unroll 3
    for (int r = 0; r < 3; ++r)
      g->t[r][l] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), m0, m1, m2) + c.tc[r];
  }
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {  // Sigma = M M^T with M = R diag(s), and T = J R_c
    float M[3][3];
#pragma GCC unroll 9
    for (int k = 0; k < 9; ++k) {
      M[k / 3][k % 3] = g->R[k][l] * g->s[k % 3][l];
      g->M[k][l] = M[k / 3][k % 3];
    }
    float S[3][3];  // (symmetric: each entry once)
    S[0][0] = DotScalarOrder(M[0][0], M[0][1], M[0][2], M[0][0], M[0][1], M[0][2]);
    S[0][1] = S[1][0] = DotScalarOrder(M[0][0], M[0][1], M[0][2], M[1][0], M[1][1], M[1][2]);
    S[0][2] = S[2][0] = DotScalarOrder(M[0][0], M[0][1], M[0][2], M[2][0], M[2][1], M[2][2]);
    S[1][1] = DotScalarOrder(M[1][0], M[1][1], M[1][2], M[1][0], M[1][1], M[1][2]);
    S[1][2] = S[2][1] = DotScalarOrder(M[1][0], M[1][1], M[1][2], M[2][0], M[2][1], M[2][2]);
    S[2][2] = DotScalarOrder(M[2][0], M[2][1], M[2][2], M[2][0], M[2][1], M[2][2]);
#pragma GCC unroll 9
    for (int k = 0; k < 9; ++k) g->S[k][l] = S[k / 3][k % 3];
    // The Jacobian of the perspective division at the clamped x/z, y/z.
    const float z = g->t[2][l];
    const float ux = g->t[0][l] / z, uy = g->t[1][l] / z;
    g->clamped_x[l] = (ux < -lim_x) | (ux > lim_x);
    g->clamped_y[l] = (uy < -lim_y) | (uy > lim_y);
    const float rx = ux < -lim_x ? -lim_x : (lim_x < ux ? lim_x : ux);
    const float ry = uy < -lim_y ? -lim_y : (lim_y < uy ? lim_y : uy);
    g->rx[l] = rx;
    g->ry[l] = ry;
    const float j00 = c.fx / z, j02 = -c.fx * rx / z, j11 = c.fy / z, j12 = -c.fy * ry / z;
#pragma GCC unroll 3
    for (int k = 0; k < 3; ++k) {
      // (Eigen's first row: its zero product and the third fused, the first added apart.)
      g->T[k][l] = j00 * Rc(0, k) + FusedMultiplyAdd(j02, Rc(2, k), 0.0f * Rc(1, k));
      g->T[3 + k][l] = DotScalarOrder(0.0f, j11, j12, Rc(0, k), Rc(1, k), Rc(2, k));
    }
  }
}

struct GaussianLanes {
  GaussianGeometry g;
  float cov[3][kLanes];  // a, b, c
  float det[kLanes], radius[kLanes], u[kLanes], v[kLanes], dir[3][kLanes];
  int ok[kLanes];  // passed every test before the tile rectangle's
};

}  // namespace

void ProjectGaussians(const GaussianModel& m, const Camera& cam, int sh_degree, bool reflection,
                      ProjectedGaussians* out) {
  const int n = static_cast<int>(m.size());
  out->Resize(n);
  const CameraLanes camera(cam);
  const Eigen::Vector3f& center = camera.center;
  const int tiles_x = (cam.width + kTileSize - 1) / kTileSize;
  const int tiles_y = (cam.height + kTileSize - 1) / kTileSize;
  const int K = m.sh_coeffs();
  const int degree = std::min(sh_degree, m.max_sh_degree);
  const int n_coeffs = (degree + 1) * (degree + 1);
  const float fx = camera.fx, fy = camera.fy, cx = camera.cx, cy = camera.cy;
  const float lim_x = FovLimit(cam.width, cam.fx), lim_y = FovLimit(cam.height, cam.fy);
  // The activations, in a loop of their own (see the top of the file).
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    out->opacity[i] = Sigmoid(m.opacity_logits[i]);
    if (reflection) {
      out->ref_opacity[i] = Sigmoid(m.ref_opacity_logits[i]);
      out->beta[i] = Sigmoid(m.beta_logits[i]);
    }
  }
  const int blocks = (n + kLanes - 1) / kLanes;
#pragma omp parallel for schedule(static)
  for (int b = 0; b < blocks; ++b) {
    GaussianLanes L;
    const int base = b * kLanes, count = std::min(kLanes, n - base);
    // Pass 1: gather, and the scales' exp.
    GatherGaussians(m, base, count, &L.g);
    // Pass 2: the geometry of every lane.
    GaussianGeometryLanes(camera, lim_x, lim_y, &L.g);
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the screen mean and the view direction
      const float t0 = L.g.t[0][l], t1 = L.g.t[1][l], t2 = L.g.t[2][l];
      L.u[l] = fx * t0 / t2 + cx;
      L.v[l] = fy * t1 / t2 + cy;
      projection_lanes::LaneNormalize(L.g.mean[0][l] - center[0], L.g.mean[1][l] - center[1],
                                      L.g.mean[2][l] - center[2], L.dir, l);
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // cov = T Sigma T^T + dilation
      float T[2][3], S[3][3];
#pragma GCC unroll 6
      for (int k = 0; k < 6; ++k) T[k / 3][k % 3] = L.g.T[k][l];
#pragma GCC unroll 9
      for (int k = 0; k < 9; ++k) S[k / 3][k % 3] = L.g.S[k][l];
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
      L.ok[l] = (L.g.t[2][l] > kNearPlane) & (det > 0) & std::isfinite(det) &
                std::isfinite(L.u[l]) & std::isfinite(L.v[l]);
    }
    for (int l = 0; l < kLanes; ++l) L.radius[l] = std::ceil(L.radius[l]);  // (not vectorised)
    // Pass 3: write out, with the alpha box.
    for (int l = 0; l < count; ++l) {
      const int i = base + l;
      out->depth[i] = L.g.t[2][l];
      out->radius[i] = 0;
      out->rects[i] = TileRect();
      out->extent[2 * i] = out->extent[2 * i + 1] = 0;
      out->min_power[i] = 0;
      const float radius = L.radius[l], u = L.u[l], v = L.v[l];
      // Visible (radius > 0, what density control reads) when the 3-sigma square meets the image.
      if (!L.ok[l] || TileRectFromBox(u, v, radius, radius, tiles_x, tiles_y).empty()) continue;
      out->radius[i] = radius;
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
      // The pixel loops blend where -conic(d) / 2 >= min_power; the 2% (1% of the width, as the
      // box's) covers their rounding of the same form.
      // (Only for rectangles binning reads them for: computed for every Gaussian they cost a
      // 256 px render more than its binning.)
      const TileRect& rect = out->rects[i];
      if (!rect.empty() && rect.x1 - rect.x0 >= kMinEllipseBinningWidth) {
        out->shapes[i] =
            TileEllipse::Of(u, v, out->conic[3 * i], out->conic[3 * i + 1], out->conic[3 * i + 2],
                            -2.0f * out->min_power[i] * 1.0201f);
      }
      for (int k = 0; k < 3; ++k) out->view_dir[3 * i + k] = L.dir[k][l];
    }
  }
  // The SH colours of the drawn Gaussians, in a loop of their own (see the top of the file).
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (i + kPrefetchAhead < n) {  // the coefficients the colours read
      const size_t ahead = static_cast<size_t>(i + kPrefetchAhead) * K * 3;
      PrefetchRow(&m.sh[ahead], 3 * n_coeffs);
      if (reflection) PrefetchRow(&m.ref_sh[ahead], 3 * n_coeffs);
    }
    if (!(out->radius[i] > 0)) continue;
    float basis[kMaxShCoeffs];  // shared by the transmitted and the reflected colour
    ShBasis(degree, &out->view_dir[3 * i], basis);
    EvalShColorFromBasis(n_coeffs, basis, &m.sh[static_cast<size_t>(i) * K * 3],
                         &out->color_t[3 * i], &out->clamp_t[3 * i]);
    if (reflection) {
      EvalShColorFromBasis(n_coeffs, basis, &m.ref_sh[static_cast<size_t>(i) * K * 3],
                           &out->color_r[3 * i], &out->clamp_r[3 * i]);
    }
  }
}

namespace {

// The backward's lanes: the geometry, the upstream gradients it needs beyond the SH colours', what
// the SH loop found for the view direction, and what it writes back.
struct GaussianGradLanes {
  GaussianGeometry g;
  float conic[3][kLanes], d_conic[3][kLanes], d_mean2d[2][kLanes], d_depth[kLanes];
  float d_dir[3][kLanes];
  // Results: the mean's gradient, d log_scales (before the scale factor), the quaternion's.
  float d_mean[3][kLanes], ds[3][kLanes], dq[4][kLanes];
  float dJ[6][kLanes], dSigma[9][kLanes];  // between the lane loops
};

}  // namespace

void ProjectGaussiansBackward(const GaussianModel& m, const Camera& cam, int sh_degree,
                              bool reflection, const ProjectedGaussians& p,
                              const ProjectedGaussiansGrad& d, GaussianGradients* grads) {
  const int n = static_cast<int>(m.size());
  const CameraLanes camera(cam);
  const Mat3& Rc = camera.Rc;
  const Eigen::Vector3f& center = camera.center;
  const float fx = camera.fx, fy = camera.fy;
  const float lim_x = FovLimit(cam.width, cam.fx), lim_y = FovLimit(cam.height, cam.fy);
  const int K = m.sh_coeffs();
  const int degree = std::min(sh_degree, m.max_sh_degree);
  const int n_coeffs = (degree + 1) * (degree + 1);
  GaussianModel& G = grads->params;
  const size_t row = static_cast<size_t>(K) * 3;  // SH floats per Gaussian
  // The activations' gradients and the screen-mean statistic, in a loop of their own (see the
  // top of the file; in the block loop these twelve arrays' loads waited on memory, `perf
  // annotate`).
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const bool drawn = p.radius[i] > 0;
    grads->mean2d[2 * i] = drawn ? 0.0f + d.mean2d[2 * i] : 0.0f;
    grads->mean2d[2 * i + 1] = drawn ? 0.0f + d.mean2d[2 * i + 1] : 0.0f;
    G.opacity_logits[i] = drawn ? SigmoidGradient(p.opacity[i], d.opacity[i]) : 0.0f;
    G.ref_opacity_logits[i] =
        drawn && reflection ? SigmoidGradient(p.ref_opacity[i], d.ref_opacity[i]) : 0.0f;
    G.beta_logits[i] = drawn && reflection ? SigmoidGradient(p.beta[i], d.beta[i]) : 0.0f;
  }
  // The SH colours' backward, in a loop of its own too: the coefficient rows read and the gradient
  // rows written (three cache lines each per colour) and the direction's gradient, kept for the
  // block loop.
  thread_local std::vector<float> dir_grad_buffer;     // (the calling thread's; the loops' threads
  dir_grad_buffer.resize(3 * static_cast<size_t>(n));  // reach it through this pointer)
  float* const dir_grad = dir_grad_buffer.data();
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (i + kPrefetchAhead < n) {  // the coefficients read, the rows written
      const size_t ahead = row * (i + kPrefetchAhead);
      PrefetchRow(&m.sh[ahead], 3 * n_coeffs);
      if (reflection) PrefetchRow(&m.ref_sh[ahead], 3 * n_coeffs);
      PrefetchRow(&G.sh[ahead], row);
      PrefetchRow(&G.ref_sh[ahead], row);
    }
    float* const d_sh = &G.sh[row * i];
    float* const d_ref_sh = &G.ref_sh[row * i];
    float* const sum_dir = &dir_grad[3 * i];
    sum_dir[0] = sum_dir[1] = sum_dir[2] = 0.0f;
    if (p.radius[i] <= 0) {  // not drawn: zero (as its other gradients)
      std::fill(d_sh, d_sh + row, 0.0f);
      std::fill(d_ref_sh, d_ref_sh + row, 0.0f);
      continue;
    }
    float basis[kMaxShCoeffs], dbasis[kMaxShCoeffs][3];
    ShBasisWithGradient(degree, &p.view_dir[3 * i], basis, dbasis);
    WriteShRowBackward(n_coeffs, basis, dbasis, &m.sh[row * i], &p.clamp_t[3 * i],
                       &d.color_t[3 * i], row, d_sh, sum_dir);
    if (reflection) {
      WriteShRowBackward(n_coeffs, basis, dbasis, &m.ref_sh[row * i], &p.clamp_r[3 * i],
                         &d.color_r[3 * i], row, d_ref_sh, sum_dir);
    } else {
      std::fill(d_ref_sh, d_ref_sh + row, 0.0f);
    }
  }
  const int blocks = (n + kLanes - 1) / kLanes;
#pragma omp parallel for schedule(static)
  for (int b = 0; b < blocks; ++b) {
    GaussianGradLanes L;
    const int base = b * kLanes, count = std::min(kLanes, n - base);
    // Pass 1: the gathers, with the view direction's gradient from the SH loop above. (Lanes past
    // the end or not drawn compute on what they hold; pass 3 skips them.)
    GatherGaussians(m, base, count, &L.g);
    for (int l = 0; l < kLanes; ++l) {
      const int i = base + (l < count ? l : 0);
      for (int k = 0; k < 3; ++k) {
        L.conic[k][l] = p.conic[3 * i + k];
        L.d_conic[k][l] = d.conic[3 * i + k];
        L.d_dir[k][l] = dir_grad[3 * i + k];  // (zero where not drawn)
      }
      for (int k = 0; k < 2; ++k) L.d_mean2d[k][l] = d.mean2d[2 * i + k];
      L.d_depth[l] = d.depth[i];
    }
    // Pass 2: the geometry, and the chain from the conic, the screen mean and the depth to the
    // mean, the scales and the rotation.
    GaussianGeometryLanes(camera, lim_x, lim_y, &L.g);
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {
      const GaussianGeometry& g = L.g;
      LaneNormalizeBackward(g.mean[0][l] - center[0], g.mean[1][l] - center[1],
                            g.mean[2][l] - center[2], L.d_dir, l, L.d_mean);
    }
    // (In four loops: as one, GCC did not vectorise it.)
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {
      const GaussianGeometry& g = L.g;
      // conic -> screen covariance: dCov = -Q dQ Q with the symmetric dQ (b appears twice).
      const float Q[2][2] = {{L.conic[0][l], L.conic[1][l]}, {L.conic[1][l], L.conic[2][l]}};
      const float hb = 0.5f * L.d_conic[1][l];
      const float dQ[2][2] = {{L.d_conic[0][l], hb}, {hb, L.d_conic[2][l]}};
      float P[2][2], dCov[2][2];
      // P = -Q dQ, each entry fused from its second product, except the last (GCC had packed it
      // with other sums).
#pragma GCC unroll 2
      for (int r = 0; r < 2; ++r) {
#pragma GCC unroll 2
        for (int c = 0; c < 2; ++c)
          P[r][c] = FusedMultiplyAdd(-Q[r][1], dQ[1][c], -Q[r][0] * dQ[0][c]);
      }
      P[1][1] = FusedMultiplyAdd(-Q[1][0], dQ[0][1], -Q[1][1] * dQ[1][1]);
#pragma GCC unroll 2
      for (int r = 0; r < 2; ++r) {
#pragma GCC unroll 2
        for (int c = 0; c < 2; ++c)
          dCov[r][c] = FusedMultiplyAdd(P[r][1], Q[1][c], P[r][0] * Q[0][c]);
      }
      // Cov = T Sigma T^T (+ dilation): dSigma = T^T dCov T, dT = 2 dCov T Sigma.
      float T[2][3], S[3][3];
#pragma GCC unroll 6
      for (int k = 0; k < 6; ++k) T[k / 3][k % 3] = g.T[k][l];
#pragma GCC unroll 9
      for (int k = 0; k < 9; ++k) S[k / 3][k % 3] = g.S[k][l];
      float TD[3][2];  // T^T dCov
#pragma GCC unroll 3
      for (int r = 0; r < 3; ++r) {
#pragma GCC unroll 2
        for (int c = 0; c < 2; ++c)
          TD[r][c] = FusedMultiplyAdd(T[1][r], dCov[1][c], T[0][r] * dCov[0][c]);
      }
      float dSigma[3][3];
#pragma GCC unroll 3
      for (int r = 0; r < 3; ++r) {
#pragma GCC unroll 3
        for (int c = 0; c < 3; ++c)
          dSigma[r][c] = FusedMultiplyAdd(TD[r][1], T[1][c], TD[r][0] * T[0][c]);
      }
      float A[2][3];  // (2 dCov) T
#pragma GCC unroll 2
      for (int r = 0; r < 2; ++r) {
#pragma GCC unroll 3
        for (int c = 0; c < 3; ++c)
          A[r][c] = FusedMultiplyAdd(2.0f * dCov[r][1], T[1][c], (2.0f * dCov[r][0]) * T[0][c]);
      }
      float dT[2][3], dJ[2][3];
#pragma GCC unroll 2
      for (int r = 0; r < 2; ++r) {
#pragma GCC unroll 3
        for (int c = 0; c < 3; ++c)
          dT[r][c] = DotScalarOrder(A[r][0], A[r][1], A[r][2], S[0][c], S[1][c], S[2][c]);
      }
#pragma GCC unroll 2
      for (int r = 0; r < 2; ++r) {
#pragma GCC unroll 3
        for (int c = 0; c < 3; ++c)
          dJ[r][c] = DotScalarOrder(dT[r][0], dT[r][1], dT[r][2], Rc(c, 0), Rc(c, 1), Rc(c, 2));
      }
#pragma GCC unroll 6
      for (int k = 0; k < 6; ++k) L.dJ[k][l] = dJ[k / 3][k % 3];
#pragma GCC unroll 9
      for (int k = 0; k < 9; ++k) L.dSigma[k][l] = dSigma[k / 3][k % 3];
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {
      const GaussianGeometry& g = L.g;
      const float z = g.t[2][l], tx = g.t[0][l], ty = g.t[1][l];
      float dJ[2][3];
#pragma GCC unroll 6
      for (int k = 0; k < 6; ++k) dJ[k / 3][k % 3] = L.dJ[k][l];
      // J entries -> view-space mean (the clamped ratio carries no gradient).
      const float mx = static_cast<float>(1 - g.clamped_x[l]);  // 0 where clamped, else 1
      const float my = static_cast<float>(1 - g.clamped_y[l]);
      const float zz = z * z, zzz = zz * z;
      float d_t[3];
      d_t[0] = FusedMultiplyAdd(dJ[0][2], -fx * mx / zz, 0.0f);
      d_t[1] = FusedMultiplyAdd(dJ[1][2], -fy * my / zz, 0.0f);
      float sz = FusedMultiplyAdd(dJ[0][0], -fx / zz, dJ[1][1] * (-fy / zz));
      sz = FusedMultiplyAdd(dJ[0][2], fx * g.rx[l] / zz + fx * mx * tx / zzz, sz);
      sz = FusedMultiplyAdd(dJ[1][2], fy * g.ry[l] / zz + fy * my * ty / zzz, sz);
      d_t[2] = 0.0f + sz;
      // Screen mean and depth.
      const float du = L.d_mean2d[0][l], dv = L.d_mean2d[1][l];
      d_t[0] = d_t[0] + du * fx / z;
      d_t[1] = d_t[1] + dv * fy / z;
      d_t[2] = d_t[2] + (-du * fx * tx / zz - dv * fy * ty / zz + L.d_depth[l]);
#pragma GCC unroll 3
      for (int r = 0; r < 3; ++r)
        L.d_mean[r][l] = (0.0f + L.d_mean[r][l]) +
                         DotScalarOrder(Rc(0, r), Rc(1, r), Rc(2, r), d_t[0], d_t[1], d_t[2]);
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {
      const GaussianGeometry& g = L.g;
      float dSigma[3][3], M[3][3];
#pragma GCC unroll 9
      for (int k = 0; k < 9; ++k) {
        dSigma[k / 3][k % 3] = L.dSigma[k][l];
        M[k / 3][k % 3] = g.M[k][l];
      }
      // Sigma = M M^T, M = R diag(s).
      float dM[3][3];
#pragma GCC unroll 3
      for (int r = 0; r < 3; ++r) {
#pragma GCC unroll 3
        for (int c = 0; c < 3; ++c)
          dM[r][c] = DotScalarOrder(2.0f * dSigma[r][0], 2.0f * dSigma[r][1], 2.0f * dSigma[r][2],
                                    M[0][c], M[1][c], M[2][c]);
      }
      float dR[9];
#pragma GCC unroll 3
      for (int k = 0; k < 3; ++k) {
        L.ds[k][l] =
            DotScalarOrder(g.R[k][l], g.R[3 + k][l], g.R[6 + k][l], dM[0][k], dM[1][k], dM[2][k]);
#pragma GCC unroll 3
        for (int r = 0; r < 3; ++r) dR[3 * r + k] = g.s[k][l] * dM[r][k];
      }
      LaneRotationBackward(g.q[0][l], g.q[1][l], g.q[2][l], g.q[3][l], dR, L.dq, l);
    }
    // Pass 3: into the model's gradients.
    for (int l = 0; l < count; ++l) {
      const int i = base + l;
      if (p.radius[i] <= 0) {  // not drawn: zero
        std::fill(&G.means[3 * i], &G.means[3 * i] + 3, 0.0f);
        std::fill(&G.log_scales[3 * i], &G.log_scales[3 * i] + 3, 0.0f);
        std::fill(&G.quats[4 * i], &G.quats[4 * i] + 4, 0.0f);
        continue;
      }
      for (int k = 0; k < 3; ++k) {
        G.means[3 * i + k] = 0.0f + L.d_mean[k][l];
        G.log_scales[3 * i + k] = FusedMultiplyAdd(L.ds[k][l], L.g.s[k][l], 0.0f);
      }
      for (int k = 0; k < 4; ++k) G.quats[4 * i + k] = 0.0f + L.dq[k][l];
    }
  }
}

}  // namespace mgsr
