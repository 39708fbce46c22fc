#include "mgsr/render/project_surfels.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

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
}

namespace {

// The forward runs over blocks of kLanes surfels in three passes: a scalar one that gathers each
// surfel's parameters into the block's lanes and takes the library calls (exp, log), short loops
// over the lanes that GCC vectorises (the geometry, the culling tests, the rows and the alpha
// reach: the bulk of the arithmetic), and a scalar one that writes what is kept and evaluates the
// SH colour (a row of coefficients per surfel). Each lane computes what the per-surfel Eigen loop
// before it computed, in its order and with its fused multiply-adds (as GCC 12 fused them for this
// file's flags): every output was the same to the bit on the benchmark scene and on scenes with
// zero quaternions, surfels behind the camera, huge and tiny scales, all four SH degrees.
using projection_lanes::DotColumnMajorRow;
using projection_lanes::DotPackedOrder;
using projection_lanes::DotScalarOrder;
using projection_lanes::FusedMultiplyAdd;
using projection_lanes::kLanes;
using projection_lanes::MaxValue;

using Mat3 = Eigen::Matrix<float, 3, 3, Eigen::RowMajor>;

struct SurfelLanes {
  // Inputs (pass 1).
  float qw[kLanes], qx[kLanes], qy[kLanes], qz[kLanes];
  float px[kLanes], py[kLanes], pz[kLanes];
  float su[kLanes], sv[kLanes], opacity[kLanes], min_power[kLanes];
  // Results (pass 2).
  float R[9][kLanes], M[9][kLanes], pv[3][kLanes];
  float mx[kLanes], my[kLanes], radius[kLanes], sign[kLanes];
  float n[3][kLanes], rows[9][kLanes], ex[kLanes], ey[kLanes], dir[3][kLanes];
  int ok[kLanes];  // passed every test before the tile rectangle's
};

}  // namespace

void ProjectSurfels(const SurfelModel& m, const Camera& cam, int sh_degree, ProjectedSurfels* out,
                    float filter_sigma) {
  const int n = static_cast<int>(m.size());
  out->Resize(n);
  const Mat3 Rc = cam.R.cast<float>();
  const Eigen::Vector3f tc = cam.t.cast<float>();
  const Eigen::Vector3f center = cam.Center().cast<float>();
  const float fx = static_cast<float>(cam.fx), fy = static_cast<float>(cam.fy);
  const float cx = static_cast<float>(cam.cx), cy = static_cast<float>(cam.cy);
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
    // Pass 1: gather, and the library calls. (Lanes past the end repeat the first surfel.)
    for (int l = 0; l < kLanes; ++l) {
      const size_t i = base + (l < count ? l : 0);
      L.qw[l] = m.quats[4 * i];
      L.qx[l] = m.quats[4 * i + 1];
      L.qy[l] = m.quats[4 * i + 2];
      L.qz[l] = m.quats[4 * i + 3];
      L.px[l] = m.means[3 * i];
      L.py[l] = m.means[3 * i + 1];
      L.pz[l] = m.means[3 * i + 2];
      L.su[l] = std::exp(m.log_scales[2 * i]);
      L.sv[l] = std::exp(m.log_scales[2 * i + 1]);
      const float opacity = Sigmoid(m.opacity_logits[i]);
      L.opacity[l] = opacity;
      L.min_power[l] = opacity > kMinBlendAlpha ? std::log(kMinBlendAlpha / opacity) : 0.0f;
    }
    // Pass 2: the geometry of every lane, in short loops GCC vectorises one by one.
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the rotation
      projection_lanes::LaneRotation(L.qw[l], L.qx[l], L.qy[l], L.qz[l], L.R, l);
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // A = R_c [s_u t_u, s_v t_v, p] + t_c e3^T, M = K A
      const float su = L.su[l], sv = L.sv[l];
      const float u0 = su * L.R[0][l], u1 = su * L.R[3][l], u2 = su * L.R[6][l];
      const float v0 = sv * L.R[1][l], v1 = sv * L.R[4][l], v2 = sv * L.R[7][l];
      float A[3][3];
      for (int r = 0; r < 3; ++r) {
        A[r][0] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), u0, u1, u2);
        A[r][1] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), v0, v1, v2);
        A[r][2] = DotScalarOrder(Rc(r, 0), Rc(r, 1), Rc(r, 2), L.px[l], L.py[l], L.pz[l]) + tc[r];
      }
      for (int c = 0; c < 3; ++c) {
        L.M[c][l] = DotScalarOrder(fx, 0.0f, cx, A[0][c], A[1][c], A[2][c]);
        L.M[3 + c][l] = DotPackedOrder(0.0f, fy, cy, A[0][c], A[1][c], A[2][c]);
        L.M[6 + c][l] = c == 0 ? DotPackedOrder(0.0f, 0.0f, 1.0f, A[0][c], A[1][c], A[2][c])
                               : DotScalarOrder(0.0f, 0.0f, 1.0f, A[0][c], A[1][c], A[2][c]);
      }
      L.pv[0][l] = A[0][2];
      L.pv[1][l] = A[1][2];
      L.pv[2][l] = A[2][2];
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the camera-facing normal
      const float r2 = L.R[2][l], r5 = L.R[5][l], r8 = L.R[8][l];
      const float nv0 = DotScalarOrder(Rc(0, 0), Rc(0, 1), Rc(0, 2), r2, r5, r8);
      const float nv1 = DotScalarOrder(Rc(1, 0), Rc(1, 1), Rc(1, 2), r2, r5, r8);
      const float nv2 = DotScalarOrder(Rc(2, 0), Rc(2, 1), Rc(2, 2), r2, r5, r8);
      const float cos = -DotScalarOrder(L.pv[0][l], L.pv[1][l], L.pv[2][l], nv0, nv1, nv2);
      const float sign = cos < 0 ? -1.0f : 1.0f;
      L.sign[l] = sign;
      L.n[0][l] = nv0 * sign;
      L.n[1][l] = nv1 * sign;
      L.n[2][l] = nv2 * sign;
      L.ok[l] = (L.pv[2][l] > kSurfelNear) & (cos != 0.0f) & std::isfinite(cos);
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // screen AABB of the projected 3-sigma disk (reference 3.2)
      const float tu0 = L.M[0][l], tu1 = L.M[1][l], tu2 = L.M[2][l];
      const float tv0 = L.M[3][l], tv1 = L.M[4][l], tv2 = L.M[5][l];
      const float tw0 = L.M[6][l], tw1 = L.M[7][l], tw2 = L.M[8][l];
      // (9 tw0^2 + (9 tw1^2 - tw2^2): GCC folded the product by -1 into a negated multiply-add.)
      const float d = FusedMultiplyAdd(kSurfelCutoff2, tw0 * tw0,
                                       FusedMultiplyAdd(-tw2, tw2, kSurfelCutoff2 * (tw1 * tw1)));
      const float f0 = kSurfelCutoff2 / d, f1 = kSurfelCutoff2 / d, f2 = -1.0f / d;
      const float mx = DotPackedOrder(f0, f1, f2, tu0 * tw0, tu1 * tw1, tu2 * tw2);
      const float my = DotPackedOrder(f0, f1, f2, tv0 * tw0, tv1 * tw1, tv2 * tw2);
      const float hx = std::sqrt(
          MaxValue(1e-4f, mx * mx - DotScalarOrder(f0, f1, f2, tu0 * tu0, tu1 * tu1, tu2 * tu2)));
      const float hy = std::sqrt(
          MaxValue(1e-4f, my * my - DotScalarOrder(f0, f1, f2, tv0 * tv0, tv1 * tv1, tv2 * tv2)));
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
      const double su = L.su[l], sv = L.sv[l];
      const double ud0 = su * double(L.R[0][l]), ud1 = su * double(L.R[3][l]),
                   ud2 = su * double(L.R[6][l]);
      const double vd0 = sv * double(L.R[1][l]), vd1 = sv * double(L.R[4][l]),
                   vd2 = sv * double(L.R[7][l]);
      const double pd0 = L.px[l], pd1 = L.py[l], pd2 = L.pz[l];
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
        L.rows[c][l] = static_cast<float>(m0 - mx * m2);
        L.rows[3 + c][l] = static_cast<float>(m1 - my * m2);
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
      const float d = r2 * (tw0 * tw0 + tw1 * tw1) - tw2 * tw2;
      const float f0 = r2 / d, f1 = r2 / d, f2 = -1.0f / d;
      const float cx_ = f0 * tu0 * tw0 + f1 * tu1 * tw1 + f2 * tu2 * tw2;
      const float cy_ = f0 * tv0 * tw0 + f1 * tv1 * tw1 + f2 * tv2 * tw2;
      const float qx = f0 * tu0 * tu0 + f1 * tu1 * tu1 + f2 * tu2 * tu2;
      const float qy = f0 * tv0 * tv0 + f1 * tv1 * tv1 + f2 * tv2 * tv2;
      const float disk_x = std::abs(cx_) + std::sqrt(std::max(0.0f, cx_ * cx_ - qx));
      const float disk_y = std::abs(cy_) + std::sqrt(std::max(0.0f, cy_ * cy_ - qy));
      const float circle = std::sqrt(r2 / inv_square);
      const float x = std::max(disk_x, circle) * 1.02f + 0.5f;
      const float y = std::max(disk_y, circle) * 1.02f + 0.5f;
      const bool reach =
          (L.opacity[l] > kMinBlendAlpha) & (d < 0.0f) & std::isfinite(x) & std::isfinite(y);
      L.ex[l] = reach ? std::min(radius, x) : radius;
      L.ey[l] = reach ? std::min(radius, y) : radius;
    }
#pragma omp simd
    for (int l = 0; l < kLanes; ++l) {  // the view direction (Eigen's normalized())
      const float dx = L.px[l] - center[0], dy = L.py[l] - center[1], dz = L.pz[l] - center[2];
      const float sq = DotScalarOrder(dx, dy, dz, dx, dy, dz);
      const float len = std::sqrt(sq);
      const float ux = dx / len, uy = dy / len, uz = dz / len;
      L.dir[0][l] = sq > 0.0f ? ux : dx;
      L.dir[1][l] = sq > 0.0f ? uy : dy;
      L.dir[2][l] = sq > 0.0f ? uz : dz;
    }
    // Pass 3: write out, and the SH colour.
    for (int l = 0; l < count; ++l) {
      const int i = base + l;
      if (i + kPrefetchAhead < n)  // the coefficients the colour reads
        PrefetchRow(&m.sh[static_cast<size_t>(i + kPrefetchAhead) * Kc * 3], 3 * n_coeffs);
      out->depth[i] = L.pv[2][l];
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
      EvalShColor(degree, &m.sh[static_cast<size_t>(i) * Kc * 3], &out->view_dir[3 * i],
                  &out->color[3 * i], &out->clamp[3 * i]);
    }
  }
}

}  // namespace mgsr
