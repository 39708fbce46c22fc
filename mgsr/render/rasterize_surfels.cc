#include "mgsr/render/rasterize_surfels.h"

#include <omp.h>

#include <algorithm>
#include <cmath>

#include "mgsr/render/raster_scratch.h"
#include "mgsr/render/simd16.h"

namespace mgsr {
namespace {

using raster_internal::ColumnWindow;
using raster_internal::EnsureImage;
using raster_internal::EnsureScratch;
using raster_internal::GatherTile;
using raster_internal::kTilePixels;
using raster_internal::PixelArrays;
using raster_internal::ReachedRange;
using raster_internal::SumEntriesPerPrimitive;
using raster_internal::TileLanes;
using raster_internal::WholeRows;
using raster_internal::WindowFor;
using simd::F16;
using simd::F8;

// Gathered per-tile fields (structure of arrays over the tile's surfels).
enum Field {
  kTu0,
  kTu1,
  kTu2,
  kTv0,
  kTv1,
  kTv2,
  kTw0,
  kTw1,
  kTw2,
  kMx,
  kMy,
  kRad,
  kOp,
  kN0,
  kN1,
  kN2,
  kC0,
  kC1,
  kC2,
  kMinPow,
  kEx,
  kEy,
  kLowPass,
  kNumFields
};
// Gradient fields per surfel.
enum GradField {
  gTu0,
  gTu1,
  gTu2,
  gTv0,
  gTv1,
  gTv2,
  gTw0,
  gTw1,
  gTw2,
  gMx,
  gMy,
  gOp,
  gN0,
  gN1,
  gN2,
  gC0,
  gC1,
  gC2,
  kGradStride
};

// The low-pass floor's offset c of rho2d (see rasterize_surfels.h): e^{-c/2} = min(1, |det J| /
// s^2) with det J = det M / T_w2^3 and s the filter's sigma (inv_square = 1 / s^2). `dc` receives
// d c / d M (row-major over the stored rows, which differ from M by row operations that keep its
// determinant) where c > 0 and not clamped.
constexpr float kMinFilterArea = 1e-6f;  // below: the filter adds nothing visible (c is capped)
inline float LowPassOffset(const float tu[3], const float tv[3], const float tw[3],
                           float inv_square, float dc[9]) {
  const float cof[9] = {
      tv[1] * tw[2] - tv[2] * tw[1], tv[2] * tw[0] - tv[0] * tw[2], tv[0] * tw[1] - tv[1] * tw[0],
      tw[1] * tu[2] - tw[2] * tu[1], tw[2] * tu[0] - tw[0] * tu[2], tw[0] * tu[1] - tw[1] * tu[0],
      tu[1] * tv[2] - tu[2] * tv[1], tu[2] * tv[0] - tu[0] * tv[2], tu[0] * tv[1] - tu[1] * tv[0]};
  const float det = tu[0] * cof[0] + tu[1] * cof[1] + tu[2] * cof[2];
  const float z = tw[2];
  const float area = inv_square * std::abs(det) / (z * z * z);
  if (dc != nullptr) std::fill(dc, dc + 9, 0.0f);
  if (!(area < 1.0f)) return 0.0f;
  if (!(area > kMinFilterArea)) return -2.0f * std::log(kMinFilterArea);
  if (dc != nullptr) {
    // c = -2 ln|det| + 6 ln z + const; d ln|det| / d M = cof / det.
    for (int q = 0; q < 9; ++q) dc[q] = -2.0f * cof[q] / det;
    dc[8] += 6.0f / z;
  }
  return -2.0f * std::log(area);
}

// Everything the pixel loops read about one surfel, packed into one row (AoS), so a tile's gather
// touches one or two cache lines per surfel instead of eight scattered arrays (on the 100k-surfel
// benchmark the gather's first load missed the cache for 45% of its samples).
//
// The row carries the area-preserving low-pass offset c too (`inv_square` > 0; 0 leaves it 0),
// once per surfel rather than once per tile entry (a log and a 3x3 determinant; a surfel has
// about four entries per view). It used to sit in a table of its own, read per entry by the
// surfel's index, a load outside the tile's batched gather that often missed the cache (perf put
// 19% of the forward's samples on it, skid included; the trained model's forward and backward
// got 3% and 1% faster without it).
// `dlow` (9 floats per surfel, or null): d c / d M of the rows that have an offset (the backward
// reads no others). Surfels in no tile are skipped; too faint to blend get c = 0. With `packed`
// null only `dlow` is computed (a backward reusing its forward's rows).
void PackSurfels(const ProjectedSurfels& p, float inv_square, std::vector<float>* dlow,
                 std::vector<float>* packed) {
  const int64_t n = static_cast<int64_t>(p.size());
  if (packed != nullptr) packed->resize(static_cast<size_t>(n) * kNumFields);
  if (dlow != nullptr) dlow->resize(static_cast<size_t>(n) * 9);
  float* out = packed != nullptr ? packed->data() : nullptr;
  float* dc = dlow != nullptr ? dlow->data() : nullptr;
#pragma omp parallel for schedule(static)
  for (int64_t g = 0; g < n; ++g) {
    if (p.rects[g].empty()) continue;  // never binned
    float low_pass = 0.0f;
    if (inv_square > 0.0f && p.opacity[g] > kMinAlpha) {
      const float* m = &p.M[9 * g];
      low_pass = LowPassOffset(m, m + 3, m + 6, inv_square, dc != nullptr ? dc + 9 * g : nullptr);
    }
    if (out == nullptr) continue;
    float* f = out + g * kNumFields;
    for (int q = 0; q < 9; ++q) f[kTu0 + q] = p.M[9 * g + q];
    f[kMx] = p.center[2 * g];
    f[kMy] = p.center[2 * g + 1];
    f[kRad] = p.radius[g];
    f[kOp] = p.opacity[g];
    for (int c = 0; c < 3; ++c) {
      f[kN0 + c] = p.normal[3 * g + c];
      f[kC0 + c] = p.color[3 * g + c];
    }
    f[kMinPow] = p.min_power[g];
    f[kEx] = p.extent[2 * g];
    f[kEy] = p.extent[2 * g + 1];
    f[kLowPass] = low_pass;
  }
}

struct Surfel {
  float tu[3], tv[3], tw[3], mx, my, rad, op, n[3], c[3];
  float low_pass;    // c: added to rho2d (PackSurfels)
  float inv_square;  // 1 / sigma^2 of the screen low-pass
  float min_power;   // below this exponent alpha < 1/255 (ProjectedSurfels::min_power)
  float ex, ey;      // where a pixel may reach 1/255 (ProjectedSurfels::extent)
  // From the surfel's packed row (PackSurfels).
  Surfel(const float* f, float inv_square_) : inv_square(inv_square_) {
    for (int q = 0; q < 3; ++q) {
      tu[q] = f[kTu0 + q];
      tv[q] = f[kTv0 + q];
      tw[q] = f[kTw0 + q];
      n[q] = f[kN0 + q];
      c[q] = f[kC0 + q];
    }
    mx = f[kMx];
    my = f[kMy];
    rad = f[kRad];
    op = f[kOp];
    min_power = f[kMinPow];
    ex = f[kEx];
    ey = f[kEy];
    low_pass = f[kLowPass];
  }
};

// The ray-splat intersection of one tile row (method.md 3.3), shared by both passes so their
// decisions agree bit for bit.
template <class V>
struct RowHit {
  using M = simd::MaskOf<V>;
  V k0, k1, k2;      // k = x T_w - T_u per lane
  float l0, l1, l2;  // l = y T_w - T_v (one value for the row)
  V p2, u, v;        // p = k x l, (u, v) = (p_x, p_y) / p_z
  V dxp;             // pixel - m (x), per lane
  float dyp;         // pixel - m (y), one value for the row
  V dxm, dym;        // m - pixel
  V rho3d, rho2d, G, z;
  M in, splat_branch;  // may contribute; rho3d <= rho2d
};

// The parts of the pixel offsets that depend only on the column (the same for every row of a
// surfel: computed once per tile entry) and only on the row. Pixel offsets from the centre m; the
// stored rows are T_u - m_x T_w and T_v - m_y T_w (see project_surfels.h), so k and l stay small
// and float keeps its precision.
template <class V>
inline void ColumnOffsets(const Surfel& s, V px, RowHit<V>* h) {
  h->dxp = px - s.mx;
  h->k0 = h->dxp * s.tw[0] - s.tu[0];
  h->k1 = h->dxp * s.tw[1] - s.tu[1];
  h->k2 = h->dxp * s.tw[2] - s.tu[2];
  h->dxm = s.mx - px;
}
template <class V>
inline void RowOffsets(const Surfel& s, float py, RowHit<V>* h) {
  h->dyp = py - s.my;
  h->l0 = h->dyp * s.tw[0] - s.tv[0];
  h->l1 = h->dyp * s.tw[1] - s.tv[1];
  h->l2 = h->dyp * s.tw[2] - s.tv[2];
  h->dym = simd::Splat<V>(s.my - py);
}

// The intersection of row py; `h` holds the surfel's ColumnOffsets.
template <class V>
inline void IntersectRow(const Surfel& s, float py, float min_power, simd::MaskOf<V> lanes_ok,
                         RowHit<V>* h) {
  using M = simd::MaskOf<V>;
  RowOffsets(s, py, h);
  const V p0 = h->k1 * h->l2 - h->k2 * h->l1;
  const V p1 = h->k2 * h->l0 - h->k0 * h->l2;
  h->p2 = h->k0 * h->l1 - h->k1 * h->l0;
  const M ok = h->p2 != 0.0f;
  const V safe_p2 = simd::Select(ok, h->p2, simd::Splat<V>(1.0f));
  h->u = p0 / safe_p2;
  h->v = p1 / safe_p2;
  h->rho3d = h->u * h->u + h->v * h->v;
  h->rho2d = s.inv_square * (h->dxm * h->dxm + h->dym * h->dym) + s.low_pass;
  h->splat_branch = h->rho3d <= h->rho2d;
  const V rho = simd::Min(h->rho3d, h->rho2d);
  // Depth: where the ray meets the disk's plane in the splat branch; the centre's depth where the
  // screen low-pass draws the surfel (as 2DGS's own rasterizer; MGSR's copy takes the plane there
  // too, method.md 3.3). Off the disk that intersection is unbounded: for a nearly edge-on surfel
  // it lies thousands of units away, and those depths made the 2DGS branch's single-iteration loss
  // spikes (up to 4.6e6) through the depth TV and distortion terms; with disks started tangent to
  // the surface (every silhouette disk edge-on) they cost the 2DGS-only method 10 dB.
  h->z = simd::Select(h->splat_branch, s.tw[0] * h->u + s.tw[1] * h->v + s.tw[2],
                      simd::Splat<V>(s.tw[2]));
  const V power = -0.5f * rho;
  // (The row itself is within the radius: callers skip rows with |m_y - y| > radius.)
  h->in =
      lanes_ok & ok & (simd::Abs(h->dxm) <= s.rad) & (h->z >= kSurfelNear) & (power >= min_power);
  h->G = simd::Exp(simd::Max(power, simd::Splat<V>(-80.0f)));
}

template <class V>
inline V NdcDepth(V z) {
  return (kSurfelFar / (kSurfelFar - kSurfelNear)) * (1.0f - kSurfelNear / z);
}

// Forward per-pixel state of a tile. A pixel that has terminated keeps its transmittance negated
// (a blending pixel's T is at least kMinTransmittance > 0): "T > 0" is its "still blending" flag,
// one array fewer to store per row (the 3DGS rasterizer does the same).
enum ForwardArray {
  aT,
  aC0,
  aC1,
  aC2,
  aDs,
  aWs,
  aN0,
  aN1,
  aN2,
  aLast,
  aZmed,
  aMed,
  aM1,
  aM2,
  aDist,
  aMref,
  kForwardArrays
};

// Blends surfel j into tile rows [ya, yb], columns [first, first + lanes of V); returns its blend
// weights there per lane, summed over the rows. kDistortion: also the distortion sums
// (SurfelRenderOptions::distortion).
template <class V, bool kDistortion>
V BlendRows(const Surfel& s, int j, float min_power, int ya, int yb, int y0, int first,
            const TileLanes& tl, const PixelArrays& st) {
  using M = simd::MaskOf<V>;
  const M lanes_ok = tl.Ok<V>(first);
  RowHit<V> cols;
  ColumnOffsets(s, tl.Px<V>(first), &cols);
  V weight_sum{};
  const float jp1 = static_cast<float>(j + 1);
  // In two loops (see the 3DGS BlendRows): first the rows' intersections and exponents, which
  // read only the "live" flags (each row is blended once per surfel, so they are those the blend
  // sees), then the blends, which need only each intersection's exponent, depth and mask.
  V G_row[kTileSize], z_row[kTileSize];
  M in_row[kTileSize];
  int row_k[kTileSize];
  int rows = 0;
  for (int y = ya; y <= yb; ++y) {
    const float py = y + 0.5f;
    const int k = (y - y0) * kTileSize + first;
    // A row whose pixels have all terminated costs one load, not the intersection and the exponent
    // (behind an opaque surface, most rows of a tile's later entries).
    const M alive = lanes_ok & (simd::Load<V>(st[aT] + k) > 0.0f);
    if (!simd::Any(alive)) continue;
    RowHit<V> h = cols;
    IntersectRow(s, py, min_power, alive, &h);
    if (!simd::Any(h.in)) continue;
    G_row[rows] = h.G;
    z_row[rows] = h.z;
    in_row[rows] = h.in;
    row_k[rows++] = k;
  }
  for (int r = 0; r < rows; ++r) {
    const V G = G_row[r], z = z_row[r];
    const M in = in_row[r];
    const int k = row_k[r];
    const V T = simd::Load<V>(st[aT] + k);
    const V a = simd::Min(s.op * G, simd::Splat<V>(kMaxAlpha));
    const M valid = in & (a >= kMinAlpha);
    const V test = T * (1.0f - a);
    const M term = valid & (test < kMinTransmittance);
    const M blend = valid & ~term;
    const V w = simd::Masked(blend, a * T);
    simd::Store(st[aC0] + k, simd::Load<V>(st[aC0] + k) + w * s.c[0]);
    simd::Store(st[aC1] + k, simd::Load<V>(st[aC1] + k) + w * s.c[1]);
    simd::Store(st[aC2] + k, simd::Load<V>(st[aC2] + k) + w * s.c[2]);
    simd::Store(st[aDs] + k, simd::Load<V>(st[aDs] + k) + w * z);
    simd::Store(st[aWs] + k, simd::Load<V>(st[aWs] + k) + w);
    simd::Store(st[aN0] + k, simd::Load<V>(st[aN0] + k) + w * s.n[0]);
    simd::Store(st[aN1] + k, simd::Load<V>(st[aN1] + k) + w * s.n[1]);
    simd::Store(st[aN2] + k, simd::Load<V>(st[aN2] + k) + w * s.n[2]);
    // Median: the last surfel blended while the incoming transmittance is above one half.
    const M med = blend & (T > 0.5f);
    simd::StoreMasked(st[aZmed] + k, med, z);
    simd::StoreMasked(st[aMed] + k, med, simd::Splat<V>(jp1));
    if constexpr (kDistortion) {
      // Distortion: w_i (m_i^2 A_i + M2_i - 2 m_i M1_i), A_i = 1 - T_i, M1/M2 over the surfels in
      // front. It only depends on differences of m, so m is taken relative to the pixel's first
      // blended surfel: in float, the absolute NDC depths (all close to 1) would cancel
      // catastrophically.
      const V m_abs = NdcDepth(simd::Select(blend, z, simd::Splat<V>(1.0f)));
      const V mref = simd::Select(blend & (simd::Load<V>(st[aLast] + k) == 0.0f), m_abs,
                                  simd::Load<V>(st[aMref] + k));
      simd::Store(st[aMref] + k, mref);
      const V m = m_abs - mref;
      const V M1 = simd::Load<V>(st[aM1] + k), M2 = simd::Load<V>(st[aM2] + k);
      simd::Store(st[aDist] + k,
                  simd::Load<V>(st[aDist] + k) + w * (m * m * (1.0f - T) + M2 - 2.0f * m * M1));
      simd::Store(st[aM1] + k, M1 + w * m);
      simd::Store(st[aM2] + k, M2 + w * m * m);
    }
    simd::Store(st[aT] + k, simd::Select(blend, test, simd::Select(term, -T, T)));
    simd::StoreMasked(st[aLast] + k, blend, simd::Splat<V>(jp1));
    weight_sum += w;
  }
  return weight_sum;
}

// d m / d z of the NDC depth m the distortion term reads.
constexpr float kDmDzScale = kSurfelFar * kSurfelNear / (kSurfelFar - kSurfelNear);

// Backward per-pixel state of a tile. The "behind" accumulator is one number per pixel, S . g
// (as in the 3DGS backward, see rasterize_gaussians.cc): what the surfels behind blend of the
// colour, depth and normal, dotted with the pixel's gradients of those outputs, plus, with the
// distortion term, what they blend of d dist / d w.
enum BackwardArray {
  bT,
  bS,
  bGc0,
  bGc1,
  bGc2,
  bGDs,
  bGn0,
  bGn1,
  bGn2,
  bTGA,  // T_N d loss / d A - T_N bg . g: the T_N terms of every d loss / d a_i, times 1 - a_i
  bGZmed,
  bGDist,
  bAN,
  bM1N,
  bM2N,
  bMref,
  bLast,
  bMed,
  kBackwardArrays
};
static_assert(kForwardArrays <= raster_internal::kMaxPixelArrays &&
                  kBackwardArrays <= raster_internal::kMaxPixelArrays,
              "EnsureScratch sizes the pixel state for kMaxPixelArrays arrays");

// Gradients of surfel j over tile rows [ya, yb], columns [first, first + lanes of V), per lane
// (summed over the rows) in `acc`: the kGradStride fields in the order of GradField, then d loss /
// d c of the low-pass offset (for WriteGradients); un-blends it from the state. kDistortion: the
// distortion output has a gradient (else its terms are zero and skipped).
constexpr int kLaneSums = 19;
template <class V, bool kDistortion>
void GradientRows(const Surfel& s, int j, float min_power, int ya, int yb, int y0, int first,
                  const TileLanes& tl, const PixelArrays& st, V acc[kLaneSums]) {
  using M = simd::MaskOf<V>;
  const M lanes_ok = tl.Ok<V>(first);
  RowHit<V> cols;
  ColumnOffsets(s, tl.Px<V>(first), &cols);
  const float jf = static_cast<float>(j);
  V glow{};  // d loss / d c (the low-pass offset)
  V gTu0{}, gTu1{}, gTu2{}, gTv0{}, gTv1{}, gTv2{}, gTw0{}, gTw1{}, gTw2{}, gmx{}, gmy{}, gop{};
  V gn0{}, gn1{}, gn2{}, gc0{}, gc1{}, gc2{};
  // In two loops (see BlendRows): the rows' intersections and exponents (which read only the
  // last-blended indices, which this pass does not write), then the un-blending and gradients.
  // Between them each row keeps only what its offsets do not give back cheaply (the column
  // offsets are the surfel's, the row offsets a few scalar products): a third of a RowHit, so
  // the rows cross the stack in a third of the stores (they bounded this loop).
  struct RowSample {
    V G, z, u, v, p2;
    M in, splat_branch;
    float py;
  };
  RowSample hit[kTileSize];
  int row_k[kTileSize];
  int rows = 0;
  for (int y = ya; y <= yb; ++y) {
    const float py = y + 0.5f;
    const int k = (y - y0) * kTileSize + first;
    // Only pixels that blended this surfel (j < last) take part; a row without any skips the
    // intersection.
    const M blended = lanes_ok & (jf < simd::Load<V>(st[bLast] + k));
    if (!simd::Any(blended)) continue;
    RowHit<V> h = cols;
    IntersectRow(s, py, min_power, blended, &h);
    if (!simd::Any(h.in)) continue;
    hit[rows] = {h.G, h.z, h.u, h.v, h.p2, h.in, h.splat_branch, py};
    row_k[rows++] = k;
  }
  for (int r = 0; r < rows; ++r) {
    const RowSample& sample = hit[r];
    RowHit<V> h = cols;
    RowOffsets(s, sample.py, &h);
    h.G = sample.G;
    h.z = sample.z;
    h.u = sample.u;
    h.v = sample.v;
    h.p2 = sample.p2;
    h.in = sample.in;
    h.splat_branch = sample.splat_branch;
    const int k = row_k[r];
    const V raw = s.op * h.G;
    const V a = simd::Min(raw, simd::Splat<V>(kMaxAlpha));
    const M valid = h.in & (a >= kMinAlpha);
    if (!simd::Any(valid)) continue;
    const V inv = 1.0f / (1.0f - a);
    const V T = simd::Select(valid, simd::Load<V>(st[bT] + k) * inv, simd::Load<V>(st[bT] + k));
    simd::Store(st[bT] + k, T);
    const V w = simd::Masked(valid, a * T);
    const V Gc0 = simd::Load<V>(st[bGc0] + k), Gc1 = simd::Load<V>(st[bGc1] + k),
            Gc2 = simd::Load<V>(st[bGc2] + k);
    const V Gn0 = simd::Load<V>(st[bGn0] + k), Gn1 = simd::Load<V>(st[bGn1] + k),
            Gn2 = simd::Load<V>(st[bGn2] + k);
    const V GDs = simd::Load<V>(st[bGDs] + k);
    gc0 += w * Gc0;
    gc1 += w * Gc1;
    gc2 += w * Gc2;
    gn0 += w * Gn0;
    gn1 += w * Gn1;
    gn2 += w * Gn2;
    // d loss / d z of the intersection.
    const M is_median = valid & (jf + 1.0f == simd::Load<V>(st[bMed] + k));
    V dz = w * GDs + simd::Masked(is_median, simd::Load<V>(st[bGZmed] + k));
    // Distortion: d dist / d w_i (its part of d loss / d a) and d dist / d m_i at this pixel's
    // totals.
    [[maybe_unused]] V gw_dist{};
    if constexpr (kDistortion) {
      const V GDist = simd::Load<V>(st[bGDist] + k);
      const V zz = simd::Select(valid, h.z, simd::Splat<V>(1.0f));
      const V m = NdcDepth(zz) - simd::Load<V>(st[bMref] + k);  // relative, as in the forward
      const V AN = simd::Load<V>(st[bAN] + k), M1N = simd::Load<V>(st[bM1N] + k),
              M2N = simd::Load<V>(st[bM2N] + k);
      gw_dist = GDist * (m * m * AN - 2.0f * m * M1N + M2N);
      const V dm = 2.0f * w * GDist * (m * AN - M1N);
      dz += dm * (kDmDzScale / (zz * zz));
    }
    // d loss / d a through every output: T (q . g - S . g) plus the T_N terms, where q . g is
    // what this surfel blends (colour, depth, normal, d dist / d w) dotted with the gradients.
    V qg = s.c[0] * Gc0 + s.c[1] * Gc1 + s.c[2] * Gc2 + h.z * GDs + s.n[0] * Gn0 + s.n[1] * Gn1 +
           s.n[2] * Gn2;
    if constexpr (kDistortion) qg += gw_dist;
    const V S = simd::Load<V>(st[bS] + k);
    const V da = (qg - S) * T + simd::Load<V>(st[bTGA] + k) * inv;
    simd::Store(st[bS] + k, simd::Select(valid, a * qg + (1.0f - a) * S, S));
    const M slope = valid & (raw < kMaxAlpha);  // the clamp at 0.99 has zero slope
    gop += simd::Masked(slope, h.G * da);
    const V dG = simd::Masked(slope, s.op * da);
    const V drho = -0.5f * h.G * dG;
    // rho = min(rho3d, rho2d): the splat branch moves (u, v), the low-pass branch the centre.
    V du = simd::Masked(h.splat_branch, 2.0f * h.u * drho);
    V dv = simd::Masked(h.splat_branch, 2.0f * h.v * drho);
    const V drho2d = simd::Masked(~h.splat_branch, drho) * (2.0f * s.inv_square);
    gmx += drho2d * h.dxm;
    gmy += drho2d * h.dym;
    glow += simd::Masked(~h.splat_branch, drho);
    // z = T_w . (u, v, 1) in the splat branch, T_w,z in the low-pass branch.
    const V dzv = simd::Masked(valid, dz);
    const V dzs = simd::Masked(h.splat_branch, dzv);
    du += dzs * s.tw[0];
    dv += dzs * s.tw[1];
    gTw0 += dzs * h.u;
    gTw1 += dzs * h.v;
    gTw2 += dzv;
    // (u, v) = (p_x, p_y) / p_z, p = k x l, k = x T_w - T_u, l = y T_w - T_v.
    const V safe_p2 = simd::Select(valid, h.p2, simd::Splat<V>(1.0f));
    const V dp0 = du / safe_p2, dp1 = dv / safe_p2, dp2 = -(h.u * du + h.v * dv) / safe_p2;
    const V dk0 = h.l1 * dp2 - h.l2 * dp1;  // dk = l x dp
    const V dk1 = h.l2 * dp0 - h.l0 * dp2;
    const V dk2 = h.l0 * dp1 - h.l1 * dp0;
    const V dl0 = dp1 * h.k2 - dp2 * h.k1;  // dl = dp x k
    const V dl1 = dp2 * h.k0 - dp0 * h.k2;
    const V dl2 = dp0 * h.k1 - dp1 * h.k0;
    gTu0 -= dk0;
    gTu1 -= dk1;
    gTu2 -= dk2;
    gTv0 -= dl0;
    gTv1 -= dl1;
    gTv2 -= dl2;
    gTw0 += h.dxp * dk0 + h.dyp * dl0;
    gTw1 += h.dxp * dk1 + h.dyp * dl1;
    gTw2 += h.dxp * dk2 + h.dyp * dl2;
    // k and l depend on the centre through the pixel offsets.
    gmx -= s.tw[0] * dk0 + s.tw[1] * dk1 + s.tw[2] * dk2;
    gmy -= s.tw[0] * dl0 + s.tw[1] * dl1 + s.tw[2] * dl2;
  }
  // In the order of GradField, then the low-pass offset's.
  const V lanes[kLaneSums] = {gTu0, gTu1, gTu2, gTv0, gTv1, gTv2, gTw0, gTw1, gTw2, gmx,
                              gmy,  gop,  gn0,  gn1,  gn2,  gc0,  gc1,  gc2,  glow};
  std::copy(lanes, lanes + kLaneSums, acc);
}

// Surfel `s`'s gradient row `dst` from GradientRows' per-lane sums (`dlow`: d c / d M of its
// low-pass offset).
template <class V>
void WriteGradients(const Surfel& s, const V acc[kLaneSums], const float dlow[9], float* dst) {
  static_assert(kGradStride == 18, "16 sums at once, then gC1 and gC2");
  simd::SumEach(acc, dst);
  dst[gC1] = simd::Sum(acc[gC1]);
  dst[gC2] = simd::Sum(acc[gC2]);
  if (s.low_pass > 0) {  // area-preserving low-pass only
    const float gl = simd::Sum(acc[kGradStride]);
    // The rows T_u, T_v, T_w lead the gradient stride (gTu0 = 0).
    for (int q = 0; q < 9; ++q) dst[q] += gl * dlow[q];
  }
}

}  // namespace

void RasterizeSurfels(const ProjectedSurfels& p, const TileBins& bins, const SurfelRenderOptions& o,
                      SurfelRender* out, RasterScratch* scratch) {
  const int W = o.camera.width, H = o.camera.height;
  const size_t npix = static_cast<size_t>(W) * H;
  EnsureImage(&out->color, W, H, 3);
  EnsureImage(&out->normal, W, H, 3);
  EnsureImage(&out->normal_world, W, H, 3);
  for (Image* im : {&out->depth, &out->alpha, &out->median_depth}) EnsureImage(im, W, H, 1);
  const bool distortion = o.distortion;
  if (distortion) {
    EnsureImage(&out->distortion, W, H, 1);
  } else {
    out->distortion = Image();
  }
  out->final_t.resize(npix);
  out->depth_sum.resize(npix);
  out->weight_sum.resize(npix);
  for (std::vector<float>* v : {&out->m1, &out->m2, &out->m_ref}) v->resize(distortion ? npix : 0);
  out->last.resize(npix);
  out->median_index.resize(npix);
  out->entry_blended.resize(bins.ids.size());
  const int threads = omp_get_max_threads();
  EnsureScratch(scratch, threads, bins, kNumFields);
  const Image* bg_image = o.background_image;
  const Eigen::Matrix3f Rt = o.camera.R.transpose().cast<float>();
  const bool area_preserving = o.low_pass == SurfelLowPass::kAreaPreserving;
  const float inv_square = 1.0f / (o.filter_sigma * o.filter_sigma);
  PackSurfels(p, area_preserving ? inv_square : 0.0f, nullptr, &scratch->packed);
  scratch->packed_from = &p;
  const float* packed = scratch->packed.data();
  // Per tile entry: the entry's summed blend weights (only when recording contributions).
  std::vector<float> entry_weight(o.record_contribution ? bins.ids.size() : 0, 0.0f);

#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int i = 0; i < bins.num_tiles(); ++i) {
    const int tile = bins.tile_order[i];
    const int thread = omp_get_thread_num();
    const int tx = tile % bins.tiles_x, ty = tile / bins.tiles_x;
    const uint32_t begin = bins.tile_start[tile];
    const int n = static_cast<int>(bins.tile_start[tile + 1] - begin);
    float* const weights = o.record_contribution ? entry_weight.data() + begin : nullptr;
    uint8_t* const blended = out->entry_blended.data() + begin;
    std::fill(blended, blended + n, uint8_t{0});
    std::vector<float>& buffer = scratch->tile_data[thread];
    const uint32_t* ids = bins.ids.data() + begin;
    buffer.resize(static_cast<size_t>(kNumFields) * n);
    const float* f = buffer.data();
    const int x0 = tx * kTileSize, y0 = ty * kTileSize;
    const int x_end = std::min(W, x0 + kTileSize), y_end = std::min(H, y0 + kTileSize);
    const TileLanes tl(x0, x_end - x0);

    const PixelArrays st(&scratch->pixel_state[thread], kForwardArrays);
    for (int a = 0; a < kForwardArrays; ++a) std::fill(st[a], st[a] + kTilePixels, 0.0f);
    std::fill(st[aT], st[aT] + kTilePixels, 1.0f);
    for (int j = 0; j < n; ++j) {
      if ((j & 31) == 31) {  // every 32 surfels, stop once all of the tile's pixels terminated
        int live = 0;
        for (int k = 0; k < kTilePixels; ++k) live |= st[aT][k] > 0.0f;
        if (live == 0) break;
      }
      if ((j & 31) == 0) GatherTile<kNumFields>(packed, ids, n, j, std::min(n, j + 32), &buffer);
      Surfel s(f + static_cast<size_t>(j) * kNumFields, inv_square);
      if (!(s.op > kMinAlpha)) continue;
      const float min_power = s.min_power;
      int ya, yb;
      ReachedRange(s.my, s.ey, y0, y_end - 1, &ya, &yb);
      const ColumnWindow win = WindowFor(s.mx, s.ex, x0);
      const auto blend = [&](auto lanes, int first, decltype(lanes)* out) {
        using V = decltype(lanes);
        *out = distortion ? BlendRows<V, true>(s, j, min_power, ya, yb, y0, first, tl, st)
                          : BlendRows<V, false>(s, j, min_power, ya, yb, y0, first, tl, st);
      };
      float sum;
      if (win.half) {
        F8 weights_by_lane;
        blend(F8{}, win.first, &weights_by_lane);
        sum = simd::Sum(weights_by_lane);
      } else {
        F16 weights_by_lane[1];
        WholeRows<1>(blend, weights_by_lane);
        sum = simd::Sum(weights_by_lane[0]);
      }
      if (weights != nullptr) weights[j] += sum;
      blended[j] = sum > 0.0f;  // a blended pixel's weight is at least kMinAlpha kMinTransmittance
    }
    // The outputs, a tile row at a time (the same operations per pixel as a scalar loop; the
    // world normals per pixel, as before).
    using raster_internal::StoreRow;
    using raster_internal::StoreRowAsUint;
    const int cols = x_end - x0;
    for (int y = y0; y < y_end; ++y) {
      const int k = (y - y0) * kTileSize;
      const size_t pix = static_cast<size_t>(y) * W + x0;
      const F16 T = simd::Abs(simd::Load(st[aT] + k));  // negated where it terminated
      const F16 A = 1.0f - T;
      for (int c = 0; c < 3; ++c) {
        const F16 bg = raster_internal::BackgroundRow(bg_image, o.background, c, pix, cols);
        StoreRow(out->color.plane(c) + pix, simd::Load(st[aC0 + c] + k) + T * bg, cols);
        StoreRow(out->normal.plane(c) + pix, simd::Load(st[aN0 + c] + k), cols);
      }
      for (int l = 0; l < cols; ++l) {
        const Eigen::Vector3f nv(st[aN0][k + l], st[aN1][k + l], st[aN2][k + l]);
        const Eigen::Vector3f nw = Rt * nv;
        for (int c = 0; c < 3; ++c) out->normal_world.plane(c)[pix + l] = nw[c];
      }
      StoreRow(out->alpha.plane(0) + pix, A, cols);
      // Normalised by the summed weights rather than 1 - T: equal in exact arithmetic, but a
      // faint pixel's 1 - T loses most of its digits (alpha 0.005: 2e-5 relative), which would
      // put one surfel's depth off its own z.
      const F16 Ds = simd::Load(st[aDs] + k), Ws = simd::Load(st[aWs] + k);
      StoreRow(out->depth.plane(0) + pix, simd::Masked(A >= kMinDepthAlpha, Ds / Ws), cols);
      StoreRow(out->median_depth.plane(0) + pix, simd::Load(st[aZmed] + k), cols);
      StoreRow(out->final_t.data() + pix, T, cols);
      StoreRow(out->depth_sum.data() + pix, Ds, cols);
      StoreRow(out->weight_sum.data() + pix, Ws, cols);
      if (distortion) {
        StoreRow(out->distortion.plane(0) + pix, simd::Load(st[aDist] + k), cols);
        StoreRow(out->m1.data() + pix, simd::Load(st[aM1] + k), cols);
        StoreRow(out->m2.data() + pix, simd::Load(st[aM2] + k), cols);
        StoreRow(out->m_ref.data() + pix, simd::Load(st[aMref] + k), cols);
      }
      StoreRowAsUint(out->last.data() + pix, simd::Load(st[aLast] + k), cols);
      StoreRowAsUint(out->median_index.data() + pix, simd::Load(st[aMed] + k), cols);
    }
  }
  if (o.record_contribution) {
    SumEntriesPerPrimitive(bins, entry_weight, p.size(), &out->contribution);
  } else {
    out->contribution.clear();
  }
}

void SurfelBackgroundGradient(const SurfelRender& r, const SurfelRenderGrad& g,
                              Image* d_background) {
  raster_internal::BackgroundGradientOf(r.final_t, r.color.width(), r.color.height(), g.color,
                                        Image(), d_background);
}

void RasterizeSurfelsBackward(const ProjectedSurfels& p, const TileBins& bins,
                              const SurfelRenderOptions& o, const SurfelRender& r,
                              const SurfelRenderGrad& g, ProjectedSurfelsGrad* d,
                              RasterScratch* scratch) {
  const int W = o.camera.width, H = o.camera.height;
  const size_t num = p.size();
  const int threads = omp_get_max_threads();
  EnsureScratch(scratch, threads, bins, kNumFields);
  const Image* bg_image = o.background_image;
  const Eigen::Matrix3f Rc = o.camera.R.cast<float>();
  const bool area_preserving = o.low_pass == SurfelLowPass::kAreaPreserving;
  const float inv_square = 1.0f / (o.filter_sigma * o.filter_sigma);
  if (scratch->packed_from != &p) {  // not the forward's projection (see RasterScratch)
    PackSurfels(p, area_preserving ? inv_square : 0.0f, &scratch->low_pass, &scratch->packed);
    scratch->packed_from = &p;
  } else if (area_preserving) {  // the forward's rows, and d c / d M
    PackSurfels(p, inv_square, &scratch->low_pass, nullptr);
  }
  const float* low_pass = scratch->low_pass.data();
  const float* packed = scratch->packed.data();
  // The distortion terms only where its output was rendered and has a gradient.
  const bool distortion = o.distortion && !g.distortion.empty();

  d->Resize(num);  // every entry is written below
  scratch->entry_grads.resize(bins.ids.size() * kGradStride);
  scratch->tile_used.assign(bins.num_tiles(), 0);
#pragma omp parallel num_threads(threads)
  {
    const int thread = omp_get_thread_num();
#pragma omp for schedule(dynamic, 1)
    for (int i = 0; i < bins.num_tiles(); ++i) {
      const int tile = bins.tile_order[i];
      const int tx = tile % bins.tiles_x, ty = tile / bins.tiles_x;
      const uint32_t begin = bins.tile_start[tile];
      const int n = static_cast<int>(bins.tile_start[tile + 1] - begin);
      if (n == 0) continue;
      std::vector<float>& buffer = scratch->tile_data[thread];
      const uint32_t* ids = bins.ids.data() + begin;
      float* tg = scratch->entry_grads.data() + static_cast<size_t>(begin) * kGradStride;
      const int x0 = tx * kTileSize, y0 = ty * kTileSize;
      const int x_end = std::min(W, x0 + kTileSize), y_end = std::min(H, y0 + kTileSize);
      const TileLanes tl(x0, x_end - x0);

      const PixelArrays st(&scratch->pixel_state[thread], kBackwardArrays);
      raster_internal::ClearBackwardState(st, kBackwardArrays, bS, bS + 1,
                                          x_end - x0 < kTileSize || y_end - y0 < kTileSize);
      // The upstream gradients, a tile row at a time (the same operations per pixel as a scalar
      // loop; an output without a gradient reads as zeros; the normals per pixel, as before).
      using raster_internal::LoadRow;
      using raster_internal::LoadRowOfUint;
      const int cols = x_end - x0;
      F16 last_max{};
      for (int y = y0; y < y_end; ++y) {
        const int k = (y - y0) * kTileSize;
        const size_t pix = static_cast<size_t>(y) * W + x0;
        // The camera-space normal gradient plus the world one rotated back (per pixel, as before).
        for (int c = 0; c < 3; ++c)
          simd::Store(st[bGn0 + c] + k,
                      F16{} + (g.normal.empty() ? F16{} : LoadRow(g.normal.plane(c) + pix, cols)));
        if (!g.normal_world.empty()) {
          for (int l = 0; l < cols; ++l) {
            Eigen::Vector3f gn(st[bGn0][k + l], st[bGn1][k + l], st[bGn2][k + l]);
            gn += Rc * Eigen::Vector3f(g.normal_world.plane(0)[pix + l],
                                       g.normal_world.plane(1)[pix + l],
                                       g.normal_world.plane(2)[pix + l]);
            for (int c = 0; c < 3; ++c) st[bGn0 + c][k + l] = gn[c];
          }
        }
        F16 gc[3];
        for (int c = 0; c < 3; ++c) {
          gc[c] = g.color.empty() ? F16{} : LoadRow(g.color.plane(c) + pix, cols);
          simd::Store(st[bGc0 + c] + k, gc[c]);
        }
        F16 a_grad = g.alpha.empty() ? F16{} : LoadRow(g.alpha.plane(0) + pix, cols), ds_grad{};
        const F16 T_final = LoadRow(r.final_t.data() + pix, cols);
        const F16 A = 1.0f - T_final;
        if (!g.depth.empty()) {
          // Depth = D / sum w (= D / A, see the forward pass). (Lanes past the image's edge read
          // zeros, 0 / 0 here: kept out, as every lane of the state must stay finite.)
          const simd::MaskOf<F16> has_depth = tl.Ok<F16>(0) & (A >= kMinDepthAlpha);
          const F16 gD = LoadRow(g.depth.plane(0) + pix, cols);
          const F16 ws = LoadRow(r.weight_sum.data() + pix, cols);
          ds_grad = simd::Masked(has_depth, gD / ws);
          a_grad = simd::Select(
              has_depth, a_grad - gD * LoadRow(r.depth_sum.data() + pix, cols) / (ws * ws), a_grad);
        }
        simd::Store(st[bGDs] + k, ds_grad);
        // The background and A terms share d T_N / d a_i = -T_N / (1 - a_i).
        const F16 bg_dot = raster_internal::BackgroundDot(bg_image, o.background, gc, pix, cols);
        simd::Store(st[bTGA] + k, T_final * (a_grad - bg_dot));
        simd::Store(st[bGZmed] + k,
                    g.median_depth.empty() ? F16{} : LoadRow(g.median_depth.plane(0) + pix, cols));
        simd::Store(st[bT] + k, T_final);
        if (distortion) {
          simd::Store(st[bGDist] + k, LoadRow(g.distortion.plane(0) + pix, cols));
          simd::Store(st[bAN] + k, A);
          simd::Store(st[bM1N] + k, LoadRow(r.m1.data() + pix, cols));
          simd::Store(st[bM2N] + k, LoadRow(r.m2.data() + pix, cols));
          simd::Store(st[bMref] + k, LoadRow(r.m_ref.data() + pix, cols));
        }
        const F16 last = LoadRowOfUint(r.last.data() + pix, cols);
        simd::Store(st[bLast] + k, last);
        simd::Store(st[bMed] + k, LoadRowOfUint(r.median_index.data() + pix, cols));
        last_max = simd::Max(last_max, last);
      }
      const int max_last = raster_internal::LargestLane(last_max);
      GatherTile<kNumFields>(packed, ids, n, 0, max_last, &buffer);
      const float* f = buffer.data();
      const uint8_t* blended = r.entry_blended.data() + begin;
      for (int j = max_last - 1; j >= 0; --j) {
        // Blended no pixel here, or invisible everywhere: no gradient (the row is written).
        if (!blended[j]) {
          std::fill(tg + static_cast<size_t>(j) * kGradStride,
                    tg + static_cast<size_t>(j + 1) * kGradStride, 0.0f);
          continue;
        }
        Surfel s(f + static_cast<size_t>(j) * kNumFields, inv_square);
        static constexpr float kNoLowPass[9] = {};
        const float* dlow =
            area_preserving ? low_pass + static_cast<size_t>(ids[j]) * 9 : kNoLowPass;
        const float min_power = s.min_power;
        int ya, yb;
        ReachedRange(s.my, s.ey, y0, y_end - 1, &ya, &yb);
        float* dst = tg + static_cast<size_t>(j) * kGradStride;
        const ColumnWindow win = WindowFor(s.mx, s.ex, x0);
        const auto gradients = [&](auto lanes, int first, decltype(lanes)* out) {
          using V = decltype(lanes);
          if (distortion) {
            GradientRows<V, true>(s, j, min_power, ya, yb, y0, first, tl, st, out);
          } else {
            GradientRows<V, false>(s, j, min_power, ya, yb, y0, first, tl, st, out);
          }
        };
        if (win.half) {
          F8 acc[kLaneSums];
          gradients(F8{}, win.first, acc);
          WriteGradients(s, acc, dlow, dst);
        } else {
          F16 acc[kLaneSums];
          WholeRows<kLaneSums>(gradients, acc);
          WriteGradients(s, acc, dlow, dst);
        }
      }
      scratch->tile_used[tile] = static_cast<uint32_t>(max_last);
    }
  }
  // Deterministic reduction (tile and entry order) into the projected-quantity gradients.
  ReduceEntryGradients<kGradStride>(bins, scratch->tile_used, scratch->entry_grads, num,
                                    &scratch->per_primitive);
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < static_cast<int64_t>(num); ++i) {
    const float* s = scratch->per_primitive.data() + static_cast<size_t>(i) * kGradStride;
    // (0 + g: a -0 sum comes out +0, as it did added into a zeroed buffer.)
    for (int q = 0; q < 9; ++q) d->M[9 * i + q] = 0.0f + s[gTu0 + q];
    d->center[2 * i] = 0.0f + s[gMx];
    d->center[2 * i + 1] = 0.0f + s[gMy];
    d->opacity[i] = 0.0f + s[gOp];
    for (int c = 0; c < 3; ++c) {
      d->normal[3 * i + c] = 0.0f + s[gN0 + c];
      d->color[3 * i + c] = 0.0f + s[gC0 + c];
    }
  }
}

}  // namespace mgsr
