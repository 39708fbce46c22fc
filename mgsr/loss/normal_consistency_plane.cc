#include "mgsr/loss/normal_consistency_plane.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "mgsr/loss/parallel_pixels.h"

namespace mgsr {
namespace {

// One row's planes and the row-local outputs the pixel body writes.
template <typename T>
struct RowView {
  const T *depth, *ray0, *ray1, *ray2;    // whole planes
  const T *n0, *n1, *n2, *alpha, *gamma;  // this row
  T* d_depth;                             // whole plane (with gradients)
  T *dn0, *dn1, *dn2;                     // this row (with gradients)
  T c0, c1, c2, gain, sigma;              // sigma: the robust scale (0: off)
  size_t row, up, down;  // offsets of this row and of the rows above and below (clamped)
  bool interior_row;
  int width;
  // Row-local: each pixel's term, its depth-gradient shares for its right (plus) and left
  // (minus) neighbours in this row, and whether it gives them (1) or not (0).
  T *term, *right, *left, *gives;
  T* self;  // one-sided: the centre's own share (null when central)
  bool one_sided;
};

// Pixel x of the row (its neighbours xl, xr: x -/+ 1, clamped at the row's ends, where the pixel
// is not interior and nothing read through them is kept; kInterior: inside the image's border). The
// operations and their order are the scalar loop's, with Eigen's 3-vector sums x + (y + z);
// branches became selects.
template <typename T, bool kGrad, bool kInterior, bool kOneSided>
[[gnu::always_inline]] inline void PixelTerm(const RowView<T>& r, int x, int xl, int xr) {
  const size_t o = r.row;
  const T gamma = r.gamma[x];
  const T nr0 = r.n0[x], nr1 = r.n1[x], nr2 = r.n2[x];
  // dy = P(x, y + 1) - P(x, y - 1), dx = P(x + 1, y) - P(x - 1, y); P = C + D ray. One-sided:
  // along an axis where one neighbour's depth jumps more than kNormalStepRatio times as far from
  // the centre's as the other's (a step, or the backdrop's depth 0 at the outline), the difference
  // of the centre and the closer neighbour. On a smooth surface the two jumps differ only by the
  // curvature, so the central difference stays: always taking the smaller jump would bias every
  // slanted pixel's normal towards the camera. hi/lo name the two ends.
  const size_t u = r.up + x, d = r.down + x, l = o + xl, rr = o + xr, c = o + x;
  constexpr bool one = kOneSided;
  const T jr = std::abs(r.depth[rr] - r.depth[c]), jl = std::abs(r.depth[c] - r.depth[l]);
  const T jd = std::abs(r.depth[d] - r.depth[c]), ju = std::abs(r.depth[c] - r.depth[u]);
  const bool step_x = one && (jr > T(kNormalStepRatio) * jl || jl > T(kNormalStepRatio) * jr);
  const bool step_y = one && (jd > T(kNormalStepRatio) * ju || ju > T(kNormalStepRatio) * jd);
  const bool hi_x_out = !step_x || jr < jl, lo_x_out = !step_x || jl < jr;  // else the centre
  const bool hi_y_out = !step_y || jd < ju, lo_y_out = !step_y || ju < jd;
  const size_t hx = hi_x_out ? rr : c, lx = lo_x_out ? l : c;
  const size_t hy = hi_y_out ? d : c, ly = lo_y_out ? u : c;
  const T dy0 = (r.c0 + r.depth[hy] * r.ray0[hy]) - (r.c0 + r.depth[ly] * r.ray0[ly]);
  const T dy1 = (r.c1 + r.depth[hy] * r.ray1[hy]) - (r.c1 + r.depth[ly] * r.ray1[ly]);
  const T dy2 = (r.c2 + r.depth[hy] * r.ray2[hy]) - (r.c2 + r.depth[ly] * r.ray2[ly]);
  const T dx0 = (r.c0 + r.depth[hx] * r.ray0[hx]) - (r.c0 + r.depth[lx] * r.ray0[lx]);
  const T dx1 = (r.c1 + r.depth[hx] * r.ray1[hx]) - (r.c1 + r.depth[lx] * r.ray1[lx]);
  const T dx2 = (r.c2 + r.depth[hx] * r.ray2[hx]) - (r.c2 + r.depth[lx] * r.ray2[lx]);
  // c = dy x dx, N_surf = c / |c| where defined.
  const T cx = dy1 * dx2 - dy2 * dx1;
  const T cy = dy2 * dx0 - dy0 * dx2;
  const T cz = dy0 * dx1 - dy1 * dx0;
  const T len = std::sqrt(cx * cx + (cy * cy + cz * cz));
  const bool defined = kInterior && len > T(0);
  const T ns0 = defined ? cx / len : T(0);
  const T ns1 = defined ? cy / len : T(0);
  const T ns2 = defined ? cz / len : T(0);
  const T a = r.alpha[x];
  const T res = T(1) - (nr0 * ns0 + (nr1 * ns1 + nr2 * ns2)) * a;
  // Robust: rho(res) = sigma res / (res + sigma), rho' = (sigma / (res + sigma))^2. Off, the
  // plain term and gradient (the selects keep their bits).
  const bool robust = r.sigma > T(0);
  const T denom = robust ? res + r.sigma : T(1);
  const T ratio = r.sigma / denom;
  r.term[x] = robust ? gamma * (res * ratio) : gamma * res;
  if constexpr (kGrad) {
    const bool contributes = gamma != T(0);
    const T s = robust ? r.gain * gamma * a * (ratio * ratio) : r.gain * gamma * a;
    r.dn0[x] = contributes ? r.dn0[x] + s * ns0 : r.dn0[x];
    r.dn1[x] = contributes ? r.dn1[x] + s * ns1 : r.dn1[x];
    r.dn2[x] = contributes ? r.dn2[x] + s * ns2 : r.dn2[x];
    // Through the normalisation, the cross product and the four depths.
    const bool flows = contributes && defined;
    const T dn0 = s * nr0, dn1 = s * nr1, dn2 = s * nr2;
    const T dot = ns0 * dn0 + (ns1 * dn1 + ns2 * dn2);
    const T dc0 = (dn0 - ns0 * dot) / len;
    const T dc1 = (dn1 - ns1 * dot) / len;
    const T dc2 = (dn2 - ns2 * dot) / len;
    // d dy = dx x dc, d dx = dc x dy (c = dy x dx).
    const T ddy0 = dx1 * dc2 - dx2 * dc1;
    const T ddy1 = dx2 * dc0 - dx0 * dc2;
    const T ddy2 = dx0 * dc1 - dx1 * dc0;
    const T ddx0 = dc1 * dy2 - dc2 * dy1;
    const T ddx1 = dc2 * dy0 - dc0 * dy2;
    const T ddx2 = dc0 * dy1 - dc1 * dy0;
    const T below = ddy0 * r.ray0[d] + (ddy1 * r.ray1[d] + ddy2 * r.ray2[d]);
    const T above = ddy0 * r.ray0[u] + (ddy1 * r.ray1[u] + ddy2 * r.ray2[u]);
    r.d_depth[d] = flows && hi_y_out ? r.d_depth[d] + below : r.d_depth[d];
    r.d_depth[u] = flows && lo_y_out ? r.d_depth[u] - above : r.d_depth[u];
    const T right = ddx0 * r.ray0[rr] + (ddx1 * r.ray1[rr] + ddx2 * r.ray2[rr]);
    const T left = ddx0 * r.ray0[l] + (ddx1 * r.ray1[l] + ddx2 * r.ray2[l]);
    r.right[x] = hi_x_out ? right : T(0);
    r.left[x] = lo_x_out ? left : T(0);
    r.gives[x] = flows ? T(1) : T(0);
    if constexpr (kOneSided) {
      // One-sided: the centre is one end of each difference.
      const T cx_share = ddx0 * r.ray0[c] + (ddx1 * r.ray1[c] + ddx2 * r.ray2[c]);
      const T cy_share = ddy0 * r.ray0[c] + (ddy1 * r.ray1[c] + ddy2 * r.ray2[c]);
      const T sx = hi_x_out ? (lo_x_out ? T(0) : -cx_share) : cx_share;
      const T sy = hi_y_out ? (lo_y_out ? T(0) : -cy_share) : cy_share;
      r.self[x] = sx + sy;
    }
  }
}

template <typename T, bool kGrad, bool kOneSided>
void RowTerms(const RowView<T>& view) {
  // A local copy: the loop's stores cannot reach it, so its pointers stay in registers and the
  // loop vectorises (through `view` every store might have changed them).
  const RowView<T> r = view;
  const int w = r.width;
  PixelTerm<T, kGrad, false, kOneSided>(r, 0, 0, w > 1 ? 1 : 0);
  if (r.interior_row) {
#pragma omp simd
    for (int x = 1; x < w - 1; ++x) PixelTerm<T, kGrad, true, kOneSided>(r, x, x - 1, x + 1);
  } else {
#pragma omp simd
    for (int x = 1; x < w - 1; ++x) PixelTerm<T, kGrad, false, kOneSided>(r, x, x - 1, x + 1);
  }
  if (w > 1) PixelTerm<T, kGrad, false, kOneSided>(r, w - 1, w - 2, w - 1);
  if constexpr (kGrad) {
    // This row's depth gradient: at x, the left neighbour's share is added, then (one-sided) the
    // pixel's own, then the right neighbour's is taken away (the order in which the scalar loop
    // reached them).
    T* g = r.d_depth + r.row;
#pragma omp simd
    for (int x = 0; x < w; ++x) {
      T v = g[x];
      if (x > 0) v = r.gives[x - 1] != T(0) ? v + r.right[x - 1] : v;
      if constexpr (kOneSided) v = r.gives[x] != T(0) ? v + r.self[x] : v;
      if (x + 1 < w) v = r.gives[x + 1] != T(0) ? v - r.left[x + 1] : v;
      g[x] = v;
    }
  }
}

template <typename T>
double NormalConsistencySumT(const NormalConsistencyPlanes<T>& p) {
  const int w = p.width, h = p.height;
  const bool grad = p.d_depth != nullptr;
  static thread_local std::vector<double> row_storage;
  row_storage.assign(h, 0.0);
  double* const row_total = row_storage.data();
  // A pixel writes the depth gradient of rows y - 1 .. y + 1: rows go in three interleaved phases
  // (y mod 3), each in parallel, so no two threads touch one row.
  for (int phase = 0; phase < 3; ++phase) {
#pragma omp parallel if (static_cast <int64_t>(w) * h >= kParallelPixels)
    {
      // Per worker: the row-local arrays and a row of ones (gamma without a mask).
      static thread_local std::vector<T> scratch;
      scratch.resize(6 * static_cast<size_t>(w));
      RowView<T> r;
      r.term = scratch.data();
      r.right = r.term + w;
      r.left = r.right + w;
      r.gives = r.left + w;
      T* ones = r.gives + w;
      for (int x = 0; x < w; ++x) ones[x] = T(1);
      r.one_sided = p.one_sided;
      r.self = p.one_sided ? ones + w : nullptr;
      r.depth = p.depth;
      r.ray0 = p.ray[0];
      r.ray1 = p.ray[1];
      r.ray2 = p.ray[2];
      r.d_depth = p.d_depth;
      r.c0 = p.center[0];
      r.c1 = p.center[1];
      r.c2 = p.center[2];
      r.gain = p.gain;
      r.sigma = p.robust_scale;
      r.width = w;
#pragma omp for schedule(static)
      for (int y = phase; y < h; y += 3) {
        const size_t o = static_cast<size_t>(y) * w;
        r.row = o;
        r.interior_row = y > 0 && y + 1 < h;
        r.up = r.interior_row ? o - w : o;
        r.down = r.interior_row ? o + w : o;
        r.n0 = p.normal[0] + o;
        r.n1 = p.normal[1] + o;
        r.n2 = p.normal[2] + o;
        r.alpha = p.alpha + o;
        r.gamma = p.mask != nullptr ? p.mask + o : ones;
        if (grad) {
          r.dn0 = p.d_normal[0] + o;
          r.dn1 = p.d_normal[1] + o;
          r.dn2 = p.d_normal[2] + o;
          if (r.one_sided) {
            RowTerms<T, true, true>(r);
          } else {
            RowTerms<T, true, false>(r);
          }
        } else if (r.one_sided) {
          RowTerms<T, false, true>(r);
        } else {
          RowTerms<T, false, false>(r);
        }
        double total = 0;
        for (int x = 0; x < w; ++x) total += r.term[x];
        row_total[y] = total;
      }
    }
  }
  double total = 0;
  for (int y = 0; y < h; ++y) total += row_total[y];
  return total;
}

}  // namespace

double NormalConsistencySum(const NormalConsistencyPlanes<float>& p) {
  return NormalConsistencySumT(p);
}

double NormalConsistencySum(const NormalConsistencyPlanes<double>& p) {
  return NormalConsistencySumT(p);
}

}  // namespace mgsr
