#include "mgsr/render/project_surfels.h"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "mgsr/core/zero_fill.h"
#include "mgsr/model/activations.h"
#include "mgsr/render/prefetch_rows.h"
#include "mgsr/render/project_gaussians.h"  // kMinBlendAlpha
#include "mgsr/render/projection_lanes.h"
#include "mgsr/render/sh.h"

namespace mgsr {

void ProjectedSurfels::Resize(size_t n) {
  M.resize(9 * n);
  center.resize(2 * n);
  radius.resize(n);
  rects.resize(n);
  depth.resize(n);
  normal.resize(3 * n);
  normal_sign.resize(n);
  opacity.resize(n);
  color.resize(3 * n);
  clamp.resize(3 * n);
  view_dir.resize(3 * n);
  min_power.resize(n);
  extent.resize(2 * n);
  shapes.resize(2 * n);
}

void ProjectedSurfelsGrad::Resize(size_t n) {
  M.resize(9 * n);
  center.resize(2 * n);
  normal.resize(3 * n);
  opacity.resize(n);
  color.resize(3 * n);
}

void ProjectedSurfelsGrad::ResizeAndZero(size_t n) {
  ZeroFill(9 * n, &M);
  ZeroFill(2 * n, &center);
  ZeroFill(3 * n, &normal);
  ZeroFill(n, &opacity);
  ZeroFill(3 * n, &color);
}

void SurfelGradients::ResizeAndZero(const SurfelModel& model) {
  ResizeForBackward(model);
  for (ParamBlock& b : params.Blocks()) ZeroFill(b.data->size(), b.data);
  ZeroFill(mean2d.size(), &mean2d);
}

void SurfelGradients::ResizeForBackward(const SurfelModel& model) {
  params.max_sh_degree = model.max_sh_degree;
  const size_t n = model.size();
  params.means.resize(3 * n);
  params.log_scales.resize(2 * n);
  params.quats.resize(4 * n);
  params.opacity_logits.resize(n);
  params.sh.resize(3 * static_cast<size_t>(params.sh_coeffs()) * n);
  mean2d.resize(2 * n);
}

namespace {

// The forward runs over blocks of kLanes surfels in three passes: a scalar one that gathers each
// surfel's parameters into the block's lanes and takes the library calls (exp, log), short loops
// over the lanes that GCC vectorises (the geometry, the culling tests, the rows and the alpha
// reach: the bulk of the arithmetic), and a scalar one that writes what is kept and evaluates the
// SH colour (a row of coefficients per surfel). Each lane computes what the per-surfel Eigen loop
// before it computed, in its order and with its fused multiply-adds, spelled out (this file is
// built without contraction): every output was the same to the bit on the benchmark scene and on
// scenes with zero quaternions, surfels behind the camera, huge and tiny scales, all four SH
// degrees.
using projection_lanes::CameraLanes;
using projection_lanes::DotColumnMajorRow;
using projection_lanes::DotPackedOrder;
using projection_lanes::DotScalarOrder;
using projection_lanes::FusedMultiplyAdd;
using projection_lanes::kLanes;
using projection_lanes::LaneNormalizeBackward;
using projection_lanes::LaneRotationBackward;
using projection_lanes::MaxValue;
using projection_lanes::SigmoidGradient;

using Mat3 = Eigen::Matrix<float, 3, 3, Eigen::RowMajor>;

// A block's surfels and their geometry, as both passes need them: the parameters (gathered by
// GatherSurfels) and the rotation R (row-major; columns t_u, t_v, t_w), the rows of
// M = K [R_c [s_u t_u, s_v t_v, p] + t_c e3^T] and the view-space centre (SurfelGeometryLanes).
struct SurfelGeometry {
  float q[4][kLanes], p[3][kLanes], su[kLanes], sv[kLanes];
  float R[9][kLanes], M[9][kLanes], pv[3][kLanes];
};

// Lanes past the end repeat the block's first surfel.
void GatherSurfels(const SurfelModel& m, int base, int count, SurfelGeometry* g) {
  for (int l = 0; l < kLanes; ++l) {
    const size_t i = base + (l < count ? l : 0);
    for (int k = 0; k < 4; ++k) g->q[k][l] = m.quats[4 * i + k];
    for (int k = 0; k < 3; ++k) g->p[k][l] = m.means[3 * i + k];
    g->su[l] = std::exp(m.log_scales[2 * i]);
    g->sv[l] = std::exp(m.log_scales[2 * i + 1]);
  }
}

void SurfelGeometryLanes(const CameraLanes& c, SurfelGeometry* g) {
  const Mat3& Rc = c.Rc;
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {  // the rotation
    projection_lanes::LaneRotation(g->q[0][l], g->q[1][l], g->q[2][l], g->q[3][l], g->R, l);
  }
#pragma omp simd
  for (int l = 0; l < kLanes; ++l) {  // A = R_c [s_u t_u, s_v t_v, p] + t_c e3^T, M = K A
    const float su = g->su[l], sv = g->sv[l];
    const float u0 = su * g->R[0][l], u1 = su * g->R[3][l], u2 = su * g->R[6][l];
    const float v0 = sv * g->R[1][l], v1 = sv * g->R[4][l], v2 = sv * g->R[7][l];
    float A[3][3];
    for (int r = 0; r < 3; ++r) {
      A[r][0] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), u0, u1, u2);
      A[r][1] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), v0, v1, v2);
      A[r][2] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), g->p[0][l], g->p[1][l], g->p[2][l]) +
                c.tc[r];
    }
    for (int k = 0; k < 3; ++k) {
      g->M[k][l] = DotScalarOrder(c.fx, 0.0f, c.cx, A[0][k], A[1][k], A[2][k]);
      g->M[3 + k][l] = DotPackedOrder(0.0f, c.fy, c.cy, A[0][k], A[1][k], A[2][k]);
      g->M[6 + k][l] = k == 0 ? DotPackedOrder(0.0f, 0.0f, 1.0f, A[0][k], A[1][k], A[2][k])
                              : DotScalarOrder(0.0f, 0.0f, 1.0f, A[0][k], A[1][k], A[2][k]);
    }
    for (int r = 0; r < 3; ++r) g->pv[r][l] = A[r][2];
  }
}

struct SurfelLanes {
  SurfelGeometry g;
  float opacity[kLanes], min_power[kLanes];
  float mx[kLanes], my[kLanes], radius[kLanes], sign[kLanes];
  float n[3][kLanes], rows[9][kLanes], ex[kLanes], ey[kLanes], dir[3][kLanes];
  int ok[kLanes];     // passed every test before the tile rectangle's
  int reach[kLanes];  // (ex, ey) bound where the disk and the circle reach 1/255
};

// The pixels where a surfel's rho3d = u^2 + v^2 <= r2 (its disk's image), as an ellipse around
// the centre m, from its rows centred on m (see the header). The pixel loops' intersection is
// p = k x l = dx c0 + dy c1 + c2 with c0 = T_v' x T_w, c1 = T_w x T_u', c2 = T_u' x T_v', and
// (u, v) = (p_x, p_y) / p_z, so the disk is p_x^2 + p_y^2 - r2 p_z^2 <= 0: a conic in (dx, dy),
// an ellipse where its quadratic part is positive definite; anything else keeps the whole box.
TileEllipse DiskEllipse(const float rows[9], float mx, float my, float r2) {
  const Eigen::Vector3d tu(rows[0], rows[1], rows[2]), tv(rows[3], rows[4], rows[5]),
      tw(rows[6], rows[7], rows[8]);
  const Eigen::Vector3d c[3] = {tv.cross(tw), tw.cross(tu), tu.cross(tv)};
  double q[3][3];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j)
      q[i][j] = c[i][0] * c[j][0] + c[i][1] * c[j][1] - r2 * c[i][2] * c[j][2];
  }
  const double det = q[0][0] * q[1][1] - q[0][1] * q[0][1];
  if (!(q[0][0] > 0 && det > 0)) return TileEllipse();
  // The centre e solves Q2 e = -(q02, q12); the form is (d - e)^T Q2 (d - e) <= -f, with f its
  // value at e. Scaled by 1 / q00 (which keeps the floats in range).
  const double e0 = -(q[1][1] * q[0][2] - q[0][1] * q[1][2]) / det;
  const double e1 = -(q[0][0] * q[1][2] - q[0][1] * q[0][2]) / det;
  const double f = q[2][2] + q[0][2] * e0 + q[1][2] * e1;
  const double s = 1.0 / q[0][0];
  return TileEllipse::Of(static_cast<float>(mx + e0), static_cast<float>(my + e1), 1.0f,
                         static_cast<float>(q[0][1] * s), static_cast<float>(q[1][1] * s),
                         static_cast<float>(-f * s));
}

}  // namespace

void ProjectSurfels(const SurfelModel& m, const Camera& cam, int sh_degree, ProjectedSurfels* out,
                    float filter_sigma) {
  const int n = static_cast<int>(m.size());
  out->Resize(n);
  const CameraLanes camera(cam);
  const Mat3& Rc = camera.Rc;
  const Eigen::Vector3f& center = camera.center;
  const float fx = camera.fx, fy = camera.fy, cx = camera.cx, cy = camera.cy;
  const Eigen::Matrix3d Rd = cam.R;
  const Eigen::Vector3d td = cam.t;
  const int tiles_x = (cam.width + kTileSize - 1) / kTileSize;
  const int tiles_y = (cam.height + kTileSize - 1) / kTileSize;
  const int Kc = m.sh_coeffs();
  const int degree = std::min(sh_degree, m.max_sh_degree);
  const int n_coeffs = (degree + 1) * (degree + 1);
  const float min_radius = 3.0f * filter_sigma;  // 3 sigma of the low-pass filter
  const float inv_square = 1.0f / (filter_sigma * filter_sigma);
  const int blocks = (n + kLanes - 1) / kLanes;
#pragma omp parallel for schedule(static)
  for (int b = 0; b < blocks; ++b) {
    SurfelLanes L;
    const int base = b * kLanes, count = std::min(kLanes, n - base);
    // Pass 1: gather, and the library calls.
    GatherSurfels(m, base, count, &L.g);
    for (int l = 0; l < kLanes; ++l) {
      const float opacity = Sigmoid(m.opacity_logits[base + (l < count ? l : 0)]);
      L.opacity[l] = opacity;
      L.min_power[l] = opacity > kMinBlendAlpha ? std::log(kMinBlendAlpha / opacity) : 0.0f;
    }
    // Pass 2: the geometry of every lane, in short loops GCC vectorises one by one.
    SurfelGeometryLanes(camera, &L.g);
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the camera-facing normal
      const float r2 = L.g.R[2][l], r5 = L.g.R[5][l], r8 = L.g.R[8][l];
      const float nv0 = DotScalarOrder(Rc(0, 0), Rc(0, 1), Rc(0, 2), r2, r5, r8);
      const float nv1 = DotScalarOrder(Rc(1, 0), Rc(1, 1), Rc(1, 2), r2, r5, r8);
      const float nv2 = DotScalarOrder(Rc(2, 0), Rc(2, 1), Rc(2, 2), r2, r5, r8);
      const float cos = -DotScalarOrder(L.g.pv[0][l], L.g.pv[1][l], L.g.pv[2][l], nv0, nv1, nv2);
      const float sign = cos < 0 ? -1.0f : 1.0f;
      L.sign[l] = sign;
      L.n[0][l] = nv0 * sign;
      L.n[1][l] = nv1 * sign;
      L.n[2][l] = nv2 * sign;
      L.ok[l] = (L.g.pv[2][l] > kSurfelNear) & (cos != 0.0f) & std::isfinite(cos);
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // screen AABB of the projected 3-sigma disk (method.md 3.2)
      const float tu0 = L.g.M[0][l], tu1 = L.g.M[1][l], tu2 = L.g.M[2][l];
      const float tv0 = L.g.M[3][l], tv1 = L.g.M[4][l], tv2 = L.g.M[5][l];
      const float tw0 = L.g.M[6][l], tw1 = L.g.M[7][l], tw2 = L.g.M[8][l];
      // (9 tw0^2 + (9 tw1^2 - tw2^2): GCC folded the product by -1 into a negated multiply-add.)
      const float d = FusedMultiplyAdd(kSurfelCutoff2, tw0 * tw0,
                                       FusedMultiplyAdd(-tw2, tw2, kSurfelCutoff2 * (tw1 * tw1)));
      const float f0 = kSurfelCutoff2 / d, f1 = kSurfelCutoff2 / d, f2 = -1.0f / d;
      const float mx = DotPackedOrder(f0, f1, f2, tu0 * tw0, tu1 * tw1, tu2 * tw2);
      const float my = DotPackedOrder(f0, f1, f2, tv0 * tw0, tv1 * tw1, tv2 * tw2);
      const float qx = DotScalarOrder(f0, f1, f2, tu0 * tu0, tu1 * tu1, tu2 * tu2);
      const float qy = DotScalarOrder(f0, f1, f2, tv0 * tv0, tv1 * tv1, tv2 * tv2);
      const float hx = std::sqrt(MaxValue(1e-4f, FusedMultiplyAdd(mx, mx, -qx)));
      const float hy = std::sqrt(MaxValue(1e-4f, FusedMultiplyAdd(my, my, -qy)));
      L.mx[l] = mx;
      L.my[l] = my;
      L.radius[l] = MaxValue(MaxValue(hx, hy), min_radius);  // before its ceil, below
      L.ok[l] = L.ok[l] & (d != 0.0f) & std::isfinite(d) & std::isfinite(mx) & std::isfinite(my);
    }
    for (int l = 0; l < kLanes; ++l) {  // (GCC does not vectorise ceilf under -ftrapping-math)
      L.radius[l] = std::ceil(L.radius[l]);
      L.ok[l] = L.ok[l] & std::isfinite(L.radius[l]);
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the rows again in double, centred on m (see the header)
      const double su = L.g.su[l], sv = L.g.sv[l];
      const double ud0 = su * double(L.g.R[0][l]), ud1 = su * double(L.g.R[3][l]),
                   ud2 = su * double(L.g.R[6][l]);
      const double vd0 = sv * double(L.g.R[1][l]), vd1 = sv * double(L.g.R[4][l]),
                   vd2 = sv * double(L.g.R[7][l]);
      const double pd0 = L.g.p[0][l], pd1 = L.g.p[1][l], pd2 = L.g.p[2][l];
      double Ad[3][3];
      for (int r = 0; r < 3; ++r) {
        Ad[r][0] = DotColumnMajorRow(r, Rd(r, 0), Rd(r, 1), Rd(r, 2), ud0, ud1, ud2);
        Ad[r][1] = DotColumnMajorRow(r, Rd(r, 0), Rd(r, 1), Rd(r, 2), vd0, vd1, vd2);
        Ad[r][2] = DotColumnMajorRow(r, Rd(r, 0), Rd(r, 1), Rd(r, 2), pd0, pd1, pd2) + td[r];
      }
      const double mx = L.mx[l], my = L.my[l];
      // The float intrinsics in double, converted here: GCC 12 at -O3 (SLP) dropped the rounding
      // to float of `const double fxd = static_cast<float>(cam.fx)` written beside the float ones.
      const double fxd = fx, fyd = fy, cxd = cx, cyd = cy;
      for (int c = 0; c < 3; ++c) {
        const double m0 = DotColumnMajorRow(0, fxd, 0.0, cxd, Ad[0][c], Ad[1][c], Ad[2][c]);
        const double m1 = DotColumnMajorRow(1, 0.0, fyd, cyd, Ad[0][c], Ad[1][c], Ad[2][c]);
        const double m2 = DotColumnMajorRow(2, 0.0, 0.0, 1.0, Ad[0][c], Ad[1][c], Ad[2][c]);
        L.rows[c][l] = static_cast<float>(FusedMultiplyAdd(-mx, m2, m0));
        L.rows[3 + c][l] = static_cast<float>(FusedMultiplyAdd(-my, m2, m1));
        L.rows[6 + c][l] = static_cast<float>(m2);
      }
    }
    // The half-extents (ex, ey) around the centre beyond which no pixel of a surfel reaches alpha
    // 1/255, i.e. rho = min(rho3d, rho2d) <= r2 = -2 min_power: the bounding box of the image of
    // the disk u^2 + v^2 <= r2 (a conic; the box as for the 3-sigma one, from the stored rows) and
    // of the low-pass circle |pixel - m|^2 <= r2 sigma^2 (its widest: the area-preserving offset
    // only shrinks it), widened by 2% and half a pixel against float rounding in the pixel loops,
    // and at most `radius` (which they are where the opacity is below 1/255 or the disk is not all
    // in front of the camera). (Tested against the per-pixel reference renderer, which has no such
    // box.)
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {
      const float tu0 = L.rows[0][l], tu1 = L.rows[1][l], tu2 = L.rows[2][l];
      const float tv0 = L.rows[3][l], tv1 = L.rows[4][l], tv2 = L.rows[5][l];
      const float tw0 = L.rows[6][l], tw1 = L.rows[7][l], tw2 = L.rows[8][l];
      const float radius = L.radius[l];
      const float r2 = -2.0f * L.min_power[l];
      const float d = FusedMultiplyAdd(r2, FusedMultiplyAdd(tw0, tw0, tw1 * tw1), -(tw2 * tw2));
      const float f0 = r2 / d, f1 = r2 / d, f2 = -1.0f / d;
      const float a0 = f0 * tu0, a1 = f1 * tu1, a2 = f2 * tu2;
      const float b0 = f0 * tv0, b1 = f1 * tv1, b2 = f2 * tv2;
      const float cx_ = FusedMultiplyAdd(a2, tw2, FusedMultiplyAdd(a0, tw0, a1 * tw1));
      const float cy_ = FusedMultiplyAdd(b2, tw2, FusedMultiplyAdd(b0, tw0, b1 * tw1));
      const float qx = FusedMultiplyAdd(a2, tu2, FusedMultiplyAdd(a0, tu0, a1 * tu1));
      const float qy = FusedMultiplyAdd(b2, tv2, FusedMultiplyAdd(b0, tv0, b1 * tv1));
      const float disk_x =
          std::abs(cx_) + std::sqrt(MaxValue(0.0f, FusedMultiplyAdd(cx_, cx_, -qx)));
      const float disk_y =
          std::abs(cy_) + std::sqrt(MaxValue(0.0f, FusedMultiplyAdd(cy_, cy_, -qy)));
      const float circle = std::sqrt(r2 / inv_square);
      const float x = FusedMultiplyAdd(MaxValue(disk_x, circle), 1.02f, 0.5f);
      const float y = FusedMultiplyAdd(MaxValue(disk_y, circle), 1.02f, 0.5f);
      const bool reach =
          (L.opacity[l] > kMinBlendAlpha) & (d < 0.0f) & std::isfinite(x) & std::isfinite(y);
      L.ex[l] = reach ? std::min(radius, x) : radius;
      L.ey[l] = reach ? std::min(radius, y) : radius;
      L.reach[l] = reach;
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the view direction
      projection_lanes::LaneNormalize(L.g.p[0][l] - center[0], L.g.p[1][l] - center[1],
                                      L.g.p[2][l] - center[2], L.dir, l);
    }
    // Pass 3: write out.
    for (int l = 0; l < count; ++l) {
      const int i = base + l;
      out->depth[i] = L.g.pv[2][l];
      out->radius[i] = 0;
      out->rects[i] = TileRect();
      if (!L.ok[l]) continue;
      const float mx = L.mx[l], my = L.my[l], radius = L.radius[l];
      const TileRect rect = TileRectFromBox(mx, my, radius, radius, tiles_x, tiles_y);
      if (rect.empty()) continue;
      out->radius[i] = radius;
      out->center[2 * i] = mx;
      out->center[2 * i + 1] = my;
      for (int k = 0; k < 9; ++k) out->M[9 * i + k] = L.rows[k][l];
      for (int k = 0; k < 3; ++k) {
        out->normal[3 * i + k] = L.n[k][l];
        out->view_dir[3 * i + k] = L.dir[k][l];
      }
      out->normal_sign[i] = L.sign[l];
      const float opacity = L.opacity[l];
      out->opacity[i] = opacity;
      out->min_power[i] = L.min_power[l];
      out->extent[2 * i] = L.ex[l];
      out->extent[2 * i + 1] = L.ey[l];
      out->rects[i] = opacity > kMinBlendAlpha
                          ? TileRectFromBox(mx, my, L.ex[l], L.ey[l], tiles_x, tiles_y)
                          : rect;
      // The disk's image and the low-pass circle at its widest, as the box above; their 4% (2% of
      // the width, as the box's) covers the pixel loops' rounding of the intersection.
      // (Only for rectangles binning reads them for: computed for every surfel they cost a 256 px
      // render more than its binning.)
      TileEllipse* shape = &out->shapes[2 * i];
      const TileRect& binned = out->rects[i];
      if (binned.x1 - binned.x0 < kMinEllipseBinningWidth) continue;
      shape[0] = shape[1] = TileEllipse();
      if (L.reach[l]) {
        const float r2 = -2.0f * L.min_power[l] * 1.0404f;
        shape[0] = DiskEllipse(&out->M[9 * i], mx, my, r2);
        shape[1] = TileEllipse::Of(mx, my, 1.0f, 0.0f, 1.0f, r2 / inv_square);
      }
    }
  }
  // The SH colours of the drawn surfels, in a loop of their own: a loop over more per-surfel
  // arrays than the hardware prefetcher follows waits on memory (as ProjectGaussians).
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (i + kPrefetchAhead < n)  // the coefficients the colour reads
      PrefetchRow(&m.sh[static_cast<size_t>(i + kPrefetchAhead) * Kc * 3], 3 * n_coeffs);
    if (!(out->radius[i] > 0)) continue;
    float basis[kMaxShCoeffs];
    ShBasis(degree, &out->view_dir[3 * i], basis);
    EvalShColorFromBasis(n_coeffs, basis, &m.sh[static_cast<size_t>(i) * Kc * 3],
                         &out->color[3 * i], &out->clamp[3 * i]);
  }
}

namespace {

// The backward's lanes: its inputs beyond the geometry, what the scalar pass found for the view
// direction, and what it writes back.
struct SurfelGradLanes {
  SurfelGeometry g;
  float dM[9][kLanes], center[2][kLanes], d_center[2][kLanes], d_normal[3][kLanes];
  float sign[kLanes], d_dir[3][kLanes];
  // Results: d log_scales (before the scale factor), the quaternion and mean gradients, mean2d.
  float ds[2][kLanes], dq[4][kLanes], d_p[3][kLanes], mean2d[2][kLanes];
};

}  // namespace

// The backward takes the SH colour's backward (a row of coefficients per surfel) in a loop of its
// own, then runs over the forward's blocks of kLanes surfels: a scalar pass gathers, the geometry
// and the chain to the parameters run in lane loops, and a scalar pass writes what each surfel got
// into the model's gradients (zero where not drawn; the bits the per-surfel loop before it added
// into zeroed buffers).
void ProjectSurfelsBackward(const SurfelModel& m, const Camera& cam, int sh_degree,
                            const ProjectedSurfels& p, const ProjectedSurfelsGrad& d,
                            SurfelGradients* grads) {
  const int n = static_cast<int>(m.size());
  const CameraLanes camera(cam);
  const Mat3& Rc = camera.Rc;
  const Eigen::Vector3f& center = camera.center;
  const float fx = camera.fx, fy = camera.fy, cx = camera.cx, cy = camera.cy;
  const int Kc = m.sh_coeffs();
  const int degree = std::min(sh_degree, m.max_sh_degree);
  SurfelModel& G = grads->params;
  const size_t row = static_cast<size_t>(Kc) * 3;  // SH floats per surfel
  const int n_coeffs = (degree + 1) * (degree + 1);
  // The SH colour's backward in a loop of its own (as ProjectGaussiansBackward), the direction's
  // gradient kept for the blocks.
  thread_local std::vector<float> dir_grad_buffer;     // (the calling thread's; the loops' threads
  dir_grad_buffer.resize(3 * static_cast<size_t>(n));  // reach it through this pointer)
  float* const dir_grad = dir_grad_buffer.data();
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (i + kPrefetchAhead < n) {  // the coefficients read, the gradient row written
      PrefetchRow(&m.sh[row * (i + kPrefetchAhead)], 3 * n_coeffs);
      PrefetchRow(&G.sh[row * (i + kPrefetchAhead)], row);
    }
    float* const d_sh = &G.sh[row * i];
    float* const d_dir = &dir_grad[3 * i];
    d_dir[0] = d_dir[1] = d_dir[2] = 0.0f;
    if (p.radius[i] <= 0) {  // not drawn: zero (as its other gradients)
      std::fill(d_sh, d_sh + row, 0.0f);
      continue;
    }
    float basis[kMaxShCoeffs], dbasis[kMaxShCoeffs][3];
    ShBasisWithGradient(degree, &p.view_dir[3 * i], basis, dbasis);
    WriteShRowBackward(n_coeffs, basis, dbasis, &m.sh[row * i], &p.clamp[3 * i], &d.color[3 * i],
                       row, d_sh, d_dir);
  }
  const int blocks = (n + kLanes - 1) / kLanes;
#pragma omp parallel for schedule(static)
  for (int b = 0; b < blocks; ++b) {
    SurfelGradLanes L;
    const int base = b * kLanes, count = std::min(kLanes, n - base);
    // Pass 1: the gathers and the opacity's gradient. (Lanes past the end repeat the block's first
    // surfel; pass 3 skips them and the surfels not drawn.)
    GatherSurfels(m, base, count, &L.g);
    for (int l = 0; l < kLanes; ++l) {
      const int i = base + (l < count ? l : 0);
      for (int k = 0; k < 9; ++k) L.dM[k][l] = d.M[9 * i + k];
      for (int k = 0; k < 2; ++k) {
        L.center[k][l] = p.center[2 * i + k];
        L.d_center[k][l] = d.center[2 * i + k];
      }
      for (int k = 0; k < 3; ++k) L.d_normal[k][l] = d.normal[3 * i + k];
      L.sign[l] = p.normal_sign[i];
      for (int k = 0; k < 3; ++k) L.d_dir[k][l] = dir_grad[3 * i + k];  // (zero where not drawn)
      if (l < count)
        G.opacity_logits[i] = p.radius[i] > 0 ? SigmoidGradient(p.opacity[i], d.opacity[i]) : 0.0f;
    }
    // Pass 2: the geometry, and the chain from M, the centre and the normal to the parameters.
    SurfelGeometryLanes(camera, &L.g);
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {
      const SurfelGeometry& g = L.g;
      LaneNormalizeBackward(g.p[0][l] - center[0], g.p[1][l] - center[1], g.p[2][l] - center[2],
                            L.d_dir, l, L.d_p);
      // d/dM from the rasterizer, plus the screen centre m = (f.(T_u o T_w), f.(T_v o T_w)).
      // Undo the centring T_u' = T_u - m_x T_w, T_v' = T_v - m_y T_w (m held as its own input).
      float dM[9];
      for (int k = 0; k < 9; ++k) dM[k] = L.dM[k][l];
      const float mcx = L.center[0][l], mcy = L.center[1][l];
      const float dTu[3] = {dM[0], dM[1], dM[2]}, dTv[3] = {dM[3], dM[4], dM[5]};
      const float Tw[3] = {g.M[6][l], g.M[7][l], g.M[8][l]};
      for (int k = 0; k < 3; ++k)
        dM[6 + k] = dM[6 + k] - FusedMultiplyAdd(mcy, dTv[k], mcx * dTu[k]);
      const float dmx =
          L.d_center[0][l] - DotPackedOrder(Tw[0], Tw[1], Tw[2], dTu[0], dTu[1], dTu[2]);
      const float dmy =
          L.d_center[1][l] - DotPackedOrder(Tw[0], Tw[1], Tw[2], dTv[0], dTv[1], dTv[2]);
      {  // (m again from T_u, T_v, T_w, as the per-surfel backward took it: in the scalar order,
         // where the forward's stored centre had the packed one)
        const float Tu[3] = {g.M[0][l], g.M[1][l], g.M[2][l]};
        const float Tv[3] = {g.M[3][l], g.M[4][l], g.M[5][l]};
        const float dd =
            FusedMultiplyAdd(kSurfelCutoff2, Tw[0] * Tw[0],
                             FusedMultiplyAdd(-Tw[2], Tw[2], kSurfelCutoff2 * (Tw[1] * Tw[1])));
        const float f[3] = {kSurfelCutoff2 / dd, kSurfelCutoff2 / dd, -1.0f / dd};
        const float mx =
            DotScalarOrder(f[0], f[1], f[2], Tu[0] * Tw[0], Tu[1] * Tw[1], Tu[2] * Tw[2]);
        const float my =
            DotScalarOrder(f[0], f[1], f[2], Tv[0] * Tw[0], Tv[1] * Tw[1], Tv[2] * Tw[2]);
        const bool moved = (dmx != 0.0f) | (dmy != 0.0f);
        for (int k = 0; k < 3; ++k) {
          const float fTw = f[k] * Tw[k];
          const float r0 = FusedMultiplyAdd(dmx, fTw, dM[k]);
          const float r1 = FusedMultiplyAdd(dmy, fTw, dM[3 + k]);
          const float a = FusedMultiplyAdd(-(2.0f * mx), fTw, f[k] * Tu[k]);
          const float b = FusedMultiplyAdd(-(2.0f * my), fTw, f[k] * Tv[k]);
          const float dTw = FusedMultiplyAdd(dmy, b, dmx * a);
          const float r2 = dM[6 + k] + dTw;
          dM[k] = moved ? r0 : dM[k];
          dM[3 + k] = moved ? r1 : dM[3 + k];
          dM[6 + k] = moved ? r2 : dM[6 + k];
        }
      }
      // Densification statistic (method.md 3.8): the centre's x_num / y_num gradients scaled
      // by the depth, in pixels.
      L.mean2d[0][l] = dM[2] * g.M[8][l];
      L.mean2d[1][l] = dM[5] * g.M[8][l];
      // M = K A: dA = K^T dM; A's columns are R_c s_u t_u, R_c s_v t_v, R_c p + t_c.
      float dA[3][3];
      for (int r = 0; r < 3; ++r) {
        // Column r of K = [fx 0 cx; 0 fy cy; 0 0 1].
        const float k0 = r == 0 ? fx : (r == 2 ? cx : 0.0f);
        const float k1 = r == 1 ? fy : (r == 2 ? cy : 0.0f), k2 = r == 2 ? 1.0f : 0.0f;
        for (int c = 0; c < 3; ++c)
          dA[r][c] = DotScalarOrder(k0, k1, k2, dM[c], dM[3 + c], dM[6 + c]);
      }
      float du[3], dv[3], dRc2[3];
      for (int r = 0; r < 3; ++r) {
        du[r] = DotScalarOrder(Rc(0, r), Rc(1, r), Rc(2, r), dA[0][0], dA[1][0], dA[2][0]);
        dv[r] = DotScalarOrder(Rc(0, r), Rc(1, r), Rc(2, r), dA[0][1], dA[1][1], dA[2][1]);
        L.d_p[r][l] = L.d_p[r][l] +
                      DotScalarOrder(Rc(0, r), Rc(1, r), Rc(2, r), dA[0][2], dA[1][2], dA[2][2]);
        // (Eigen folded the sign into R_c^T's entries.)
        const float sign = L.sign[l];
        dRc2[r] = DotPackedOrder(sign * Rc(0, r), sign * Rc(1, r), sign * Rc(2, r),
                                 L.d_normal[0][l], L.d_normal[1][l], L.d_normal[2][l]);
      }
      L.ds[0][l] = DotScalarOrder(g.R[0][l], g.R[3][l], g.R[6][l], du[0], du[1], du[2]);
      L.ds[1][l] = DotScalarOrder(g.R[1][l], g.R[4][l], g.R[7][l], dv[0], dv[1], dv[2]);
      // Normal: n = sign R_c t_w.
      float dR[9];
      for (int r = 0; r < 3; ++r) {
        dR[3 * r] = g.su[l] * du[r];
        dR[3 * r + 1] = g.sv[l] * dv[r];
        dR[3 * r + 2] = dRc2[r];
      }
      LaneRotationBackward(g.q[0][l], g.q[1][l], g.q[2][l], g.q[3][l], dR, L.dq, l);
    }
    // Pass 3: into the model's gradients.
    for (int l = 0; l < count; ++l) {
      const int i = base + l;
      if (p.radius[i] <= 0) {  // not drawn: zero
        std::fill(&grads->mean2d[2 * i], &grads->mean2d[2 * i] + 2, 0.0f);
        std::fill(&G.log_scales[2 * i], &G.log_scales[2 * i] + 2, 0.0f);
        std::fill(&G.quats[4 * i], &G.quats[4 * i] + 4, 0.0f);
        std::fill(&G.means[3 * i], &G.means[3 * i] + 3, 0.0f);
        continue;
      }
      grads->mean2d[2 * i] = L.mean2d[0][l];
      grads->mean2d[2 * i + 1] = L.mean2d[1][l];
      G.log_scales[2 * i] = FusedMultiplyAdd(L.ds[0][l], L.g.su[l], 0.0f);
      G.log_scales[2 * i + 1] = FusedMultiplyAdd(L.ds[1][l], L.g.sv[l], 0.0f);
      for (int k = 0; k < 4; ++k) G.quats[4 * i + k] = 0.0f + L.dq[k][l];
      for (int k = 0; k < 3; ++k) G.means[3 * i + k] = 0.0f + L.d_p[k][l];
    }
  }
}

}  // namespace mgsr
