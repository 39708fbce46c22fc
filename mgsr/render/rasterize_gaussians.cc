#include "mgsr/render/rasterize_gaussians.h"

#include <omp.h>

#include <algorithm>
#include <cmath>

#include "mgsr/render/raster_scratch.h"
#include "mgsr/render/simd16.h"

namespace mgsr {
namespace {

// Gathered per-tile fields (structure of arrays over the tile's Gaussians).
enum Field {
  kMx,
  kMy,
  kEx,
  kEy,
  kPowT,  // an exponent below which the transmitted chain's alpha stays under kMinAlpha
  kPowR,  // the same for the reflected chain (see PackGaussians)
  kCa,
  kCb,
  kCc,
  kOp,
  kRefOp,
  kBeta,
  kZ,
  kCt0,
  kCt1,
  kCt2,
  kCr0,
  kCr1,
  kCr2,
  kNumFields
};
// Gradient fields, per Gaussian.
enum GradField {
  gMx,
  gMy,
  gCa,
  gCb,
  gCc,
  gOp,
  gRefOp,
  gBeta,
  gZ,
  gCt0,
  gCt1,
  gCt2,
  gCr0,
  gCr1,
  gCr2,
  kGradStride
};

constexpr float kLogMinAlpha = -5.5413f;  // log(kMinAlpha) = -5.54126, rounded down

// Everything the pixel loops read about one Gaussian, packed into one row (AoS), so a tile's loop
// touches one or two cache lines per Gaussian instead of 18 scattered arrays.
void PackGaussians(const ProjectedGaussians& p, std::vector<float>* packed) {
  const int64_t n = static_cast<int64_t>(p.size());
  packed->resize(static_cast<size_t>(n) * kNumFields);
  float* out = packed->data();
#pragma omp parallel for schedule(static)
  for (int64_t g = 0; g < n; ++g) {
    float* f = out + g * kNumFields;
    if (p.rects[g].empty()) continue;  // never binned
    f[kMx] = p.mean2d[2 * g];
    f[kMy] = p.mean2d[2 * g + 1];
    f[kEx] = p.extent[2 * g];
    f[kEy] = p.extent[2 * g + 1];
    f[kCa] = p.conic[3 * g];
    f[kCb] = p.conic[3 * g + 1];
    f[kCc] = p.conic[3 * g + 2];
    f[kOp] = p.opacity[g];
    f[kRefOp] = p.ref_opacity[g];
    // Each chain's own threshold (the backward's row filter): the projection's min_power (exact,
    // from the larger opacity) for the stronger chain, a lower bound of the weaker one's (no lower
    // than min_power), so no pixel that blends is left out.
    const float min_power = p.min_power[g], op = p.opacity[g], rop = p.ref_opacity[g];
    f[kPowT] = op >= rop ? min_power
                         : std::max(min_power, raster_internal::FaintPowerBound(op, kLogMinAlpha));
    f[kPowR] = rop > op ? min_power
                        : std::max(min_power, raster_internal::FaintPowerBound(rop, kLogMinAlpha));
    f[kBeta] = p.beta[g];
    f[kZ] = p.depth[g];
    for (int c = 0; c < 3; ++c) {
      f[kCt0 + c] = p.color_t[3 * g + c];
      f[kCr0 + c] = p.color_r[3 * g + c];
    }
  }
}

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
using simd::MaskOf;

static_assert(kTileSize == 16, "one tile row is one 16-lane vector");

// One Gaussian, as the pixel loops read it (from its packed row).
struct Splat {
  float mx, my, ex, ey, pow_t, pow_r, min_power, ca, cb, cc, op, rop, beta, z, ct0, ct1, ct2, cr0,
      cr1, cr2;
  explicit Splat(const float* f)
      : mx(f[kMx]),
        my(f[kMy]),
        ex(f[kEx]),
        ey(f[kEy]),
        pow_t(f[kPowT]),
        pow_r(f[kPowR]),
        min_power(std::min(pow_t, pow_r)),  // the projection's (that of the larger opacity)
        ca(f[kCa]),
        cb(f[kCb]),
        cc(f[kCc]),
        op(f[kOp]),
        rop(f[kRefOp]),
        beta(f[kBeta]),
        z(f[kZ]),
        ct0(f[kCt0]),
        ct1(f[kCt1]),
        ct2(f[kCt2]),
        cr0(f[kCr0]),
        cr1(f[kCr1]),
        cr2(f[kCr2]) {}
};

// The exponent and the "may contribute" mask of a Gaussian over (part of) one tile row; one
// definition for both passes so their decisions agree bit for bit. `lanes_ok` masks pixels
// outside the image. (|dx| <= ex is the 3-sigma square's test where the square is the tighter
// bound; elsewhere the exponent's test implies it.)
// The fused multiply-adds are spelled out (those GCC chose for the expression
// -0.5 (a dx dx + c dy dy) - b dx dy), so both passes round alike however their loops are shaped.
template <class V>
inline V RowPower(const Splat& s, V dx, float dy, MaskOf<V> lanes_ok, MaskOf<V>* in) {
  const V quadratic = simd::Fma(s.ca * dx, dx, simd::Splat<V>(s.cc * dy * dy));
  const V power = simd::Fms(simd::Splat<V>(-0.5f), quadratic, (s.cb * dx) * dy);
  *in = lanes_ok & (simd::Abs(dx) <= s.ex) & (power <= 0.0f) & (power >= s.min_power);
  return power;
}

// The lanes (pixels inside the image) each chain of a Gaussian takes part in, one definition for
// both passes: none for a chain whose opacity is below kMinAlpha, which blends nothing anywhere
// (its alpha is at most the opacity). On a trained object, most rows on which a chain blended
// nothing were those of such Gaussians (89% of the transmitted chain's, 69% of the reflected's).
template <class V>
inline void ChainLanes(const Splat& s, const TileLanes& tl, int first, MaskOf<V>* lanes_t,
                       MaskOf<V>* lanes_r) {
  *lanes_t = s.op >= kMinAlpha ? tl.Ok<V>(first) : MaskOf<V>{};
  *lanes_r = s.rop >= kMinAlpha ? tl.Ok<V>(first) : MaskOf<V>{};
}

// Forward per-pixel state of a tile: T, Tr, colours, W and D sums and 1 + index of the last
// blended Gaussian (as float, exact below 2^24). A chain that has stopped blending (terminated,
// or the reflected chain of a render without reflection) keeps its transmittance negated: a
// blending chain's T is at least kMinTransmittance > 0, so "T > 0" is its "still blending" flag,
// and the row loops store one array less per chain (the stores bound the blend loop).
enum ForwardArray {
  aT,
  aTr,
  aCt0,
  aCt1,
  aCt2,
  aCr0,
  aCr1,
  aCr2,
  aWs,
  aDs,
  aLastT,
  aLastR,
  kForwardArrays
};

// The arrays of one blending chain: transmitted or reflected.
struct ChainArrays {
  ForwardArray T, c0, c1, c2, last;
};
constexpr ChainArrays kTransmittedChain{aT, aCt0, aCt1, aCt2, aLastT};
constexpr ChainArrays kReflectedChain{aTr, aCr0, aCr1, aCr2, aLastR};

// Blends one chain of a Gaussian (its opacity and colour) into the pixels `in` of a row at `k`:
// front-to-back alpha blending with early termination. Returns the blend weights.
template <class V>
inline V BlendChain(const ChainArrays& a, const PixelArrays& st, int k, MaskOf<V> in, V G,
                    float opacity, float c0, float c1, float c2, float jp1) {
  using M = MaskOf<V>;
  const V T = simd::Load<V>(st[a.T] + k);
  const V alpha = simd::Min(opacity * G, simd::Splat<V>(kMaxAlpha));
  const M valid = in & (T > 0.0f) & (alpha >= kMinAlpha);
  const V test = T * (1.0f - alpha);
  const M terminate = valid & (test < kMinTransmittance);
  const M blend = valid & ~terminate;
  const V w = simd::Masked(blend, alpha * T);
  simd::Store(st[a.c0] + k, simd::Load<V>(st[a.c0] + k) + w * c0);
  simd::Store(st[a.c1] + k, simd::Load<V>(st[a.c1] + k) + w * c1);
  simd::Store(st[a.c2] + k, simd::Load<V>(st[a.c2] + k) + w * c2);
  simd::Store(st[a.T] + k, simd::Select(blend, test, simd::Select(terminate, -T, T)));
  simd::StoreMasked(st[a.last] + k, blend, simd::Splat<V>(jp1));
  return w;
}

// Blends Gaussian j (row `s`) into tile rows [ya, yb], columns [first, first + lanes of V).
// Returns its blend weights there per lane, summed over the rows (both chains).
//
// In two loops: first every row's exponent (which reads no state a blend writes), then the blends.
// In one loop each row's blend waited on its exponent's long dependency chain (the polynomial) and
// the next row's could not start, the out-of-order window being a row or two; apart, the exponents
// of all rows overlap and the blends are short chains (on a trained object's 3DGS branch, ms per
// view: forward 12.2 -> 10.4, backward 16.7 -> 12.0; mgsr_trained_render_bench).
template <class V>
V BlendRows(const Splat& s, int j, int ya, int yb, int y0, int first, const TileLanes& tl,
            bool refl, const PixelArrays& st) {
  using M = MaskOf<V>;
  const float jp1 = static_cast<float>(j + 1);
  const V dx = tl.Px<V>(first) - s.mx;
  M lanes_t, lanes_r;
  ChainLanes<V>(s, tl, first, &lanes_t, &lanes_r);
  // The rows that blend anything: their exponent, masks and pixel index.
  V G[kTileSize];
  M in[kTileSize], live_t[kTileSize], live_r[kTileSize];
  int row_k[kTileSize];
  int rows = 0;
  for (int y = ya; y <= yb; ++y) {
    const float dy = y + 0.5f - s.my;
    const int k = (y - y0) * kTileSize + first;
    // Pixels whose chains have both terminated take no part: a row of them costs the exponent's
    // argument, not the exponent and the blends (behind an opaque surface, most rows of a tile's
    // later entries). A chain whose pixels here have all terminated is skipped too (it would blend
    // nothing): behind an opaque surface the reflected chain, with its lower opacities, often runs
    // on alone. (Each row is blended once per Gaussian, so its flags here are those the blend
    // sees.) (Unlike the backward's first loop this one keeps its branches: computing every row's
    // exponent without them was slower here, 6.1-6.4 -> 6.5-6.9 ms per trained view, as most rows
    // behind an opaque surface are skipped.)
    const M lt = lanes_t & (simd::Load<V>(st[aT] + k) > 0.0f);
    const M lr = lanes_r & (simd::Load<V>(st[aTr] + k) > 0.0f);
    const V power = RowPower(s, dx, dy, lt | lr, &in[rows]);
    if (!simd::Any(in[rows])) continue;
    G[rows] = simd::Exp(simd::Max(power, simd::Splat<V>(-80.0f)));
    live_t[rows] = lt;
    live_r[rows] = lr;
    row_k[rows++] = k;
  }
  V weight_sum{};
  for (int r = 0; r < rows; ++r) {
    const int k = row_k[r];
    if (simd::Any(in[r] & live_t[r])) {
      const V wt =
          BlendChain(kTransmittedChain, st, k, in[r], G[r], s.op, s.ct0, s.ct1, s.ct2, jp1);
      simd::Store(st[aWs] + k, simd::Load<V>(st[aWs] + k) + wt * s.beta);
      simd::Store(st[aDs] + k, simd::Load<V>(st[aDs] + k) + wt * s.z);
      weight_sum += wt;
    }
    if (refl && simd::Any(in[r] & live_r[r]))
      weight_sum +=
          BlendChain(kReflectedChain, st, k, in[r], G[r], s.rop, s.cr0, s.cr1, s.cr2, jp1);
  }
  return weight_sum;
}

// Backward per-pixel state of a tile, walking back to front: transmittances, "behind"
// accumulators, the upstream gradients folded onto the chains (C = C_tran + W C_ref,
// D = Dsum / A) and the last-blended indices. Pixels outside the image keep last = 0 and take no
// part.
//
// A chain's "behind" accumulator is kept as one number per pixel, not one per blended quantity.
// Un-blending Gaussian i needs S_i . g, where S_i = sum_{k>i} q_k a_k prod_{i<m<k} (1 - a_m) is
// what the Gaussians behind it blend of the quantities q (colour, and for the transmitted chain
// beta and depth) and g the pixel's upstream gradients of those outputs. g is the same for every
// Gaussian of the pixel, so S_i . g follows the same recursion as S_i:
//   S_{i-1} . g = a_i (q_i . g) + (1 - a_i) (S_i . g),
// and d loss / d a_i = T_i (q_i . g - S_i . g) + (the T_N terms). One array per chain instead of
// five and three: per row of the un-blending 6 loads and 6 stores fewer.
enum BackwardArray {
  bT,
  bTr,
  bSt,  // S . g of the transmitted chain (colour, beta, depth)
  bSr,  // S . g of the reflected chain (colour)
  bGt0,
  bGt1,
  bGt2,
  bGr0,
  bGr1,
  bGr2,
  bGW,
  bGN,
  bTGA,  // T_N d loss / d A - T_N bg . g: the T_N terms of every d loss / d a_i, times 1 - a_i
  bLastT,
  bLastR,
  kBackwardArrays
};
static_assert(kForwardArrays <= raster_internal::kMaxPixelArrays &&
                  kBackwardArrays <= raster_internal::kMaxPixelArrays,
              "EnsureScratch sizes the pixel state for kMaxPixelArrays arrays");

// Gradients of Gaussian j (row `s`) over tile rows [ya, yb], columns [first, first + lanes of
// V), per lane in the order of GradField (summed over the rows; `acc[15]` pads), for
// WriteGradients; un-blends it from the pixel state. In two loops, as BlendRows: the rows'
// exponents (which read only the last-blended indices, which this pass does not write), then the
// un-blending and the gradients.
template <class V>
void GradientRows(const Splat& s, int j, int ya, int yb, int y0, int first, const TileLanes& tl,
                  bool refl, const PixelArrays& st, V acc[16]) {
  using M = MaskOf<V>;
  const float jf = static_cast<float>(j);
  const V dx = tl.Px<V>(first) - s.mx;
  M lanes_t, lanes_r;
  ChainLanes<V>(s, tl, first, &lanes_t, &lanes_r);
  // The rows where a pixel blended this Gaussian: exponent (its argument until the second loop),
  // mask, offset and index.
  V G_row[kTileSize];
  M in_row[kTileSize];
  float dy_row[kTileSize];
  int row_k[kTileSize];
  int rows = 0;
  // Without branches: every row of the box gets its exponent's argument, and is kept (the count
  // moves on) when a pixel of it blended this Gaussian (j < last) inside the ellipse. Which rows
  // those are changes from entry to entry, and the branches that skipped the others were
  // mispredicted often enough to cost more than the exponents they saved. The exponents follow,
  // for the kept rows only (on a trained object a third of the box rows are dropped, and the
  // exponent was most of this loop).
  for (int y = ya; y <= yb; ++y) {
    const float dy = y + 0.5f - s.my;
    const int k = (y - y0) * kTileSize + first;
    const V last_t = simd::Load<V>(st[bLastT] + k), last_r = simd::Load<V>(st[bLastR] + k);
    const M blended_t = lanes_t & (jf < last_t), blended_r = lanes_r & (jf < last_r);
    const V power = RowPower(s, dx, dy, blended_t | blended_r, &in_row[rows]);
    // Each chain's pixels within its own threshold (the weaker chain's footprint is the smaller
    // one): rows that only the weaker chain blended, outside its footprint, are not kept. (The
    // forward keeps the one test for both chains: there the compares cost more than the rows they
    // dropped, 100k raster forward 11.3 -> 12.0 ms.)
    in_row[rows] &= (blended_t & (power >= s.pow_t)) | (blended_r & (power >= s.pow_r));
    G_row[rows] = power;
    dy_row[rows] = dy;
    row_k[rows] = k;
    rows += simd::Any(in_row[rows]);
  }
  for (int r = 0; r < rows; ++r) G_row[r] = simd::Exp(simd::Max(G_row[r], simd::Splat<V>(-80.0f)));
  // d power / d (screen mean, conic) at a pixel are a dx + b dy, b dx + c dy, -dx^2 / 2, -dx dy
  // and -dy^2 / 2: dx is the lane's, dy the row's. So the rows sum d loss / d power times dy and
  // dy^2 per lane (its plain sum is o g_op + or g_rop, see below), and the five gradients come
  // from those sums once per entry: two accumulations per row instead of five, and a dozen
  // operations fewer.
  V sum_dp_dy{}, sum_dp_dy2{};
  V g_op{}, g_rop{}, g_beta{}, g_z{};
  V g_ct0{}, g_ct1{}, g_ct2{}, g_cr0{}, g_cr1{}, g_cr2{};
  for (int r = 0; r < rows; ++r) {
    const V G = G_row[r];
    const M in = in_row[r];
    const float dy = dy_row[r];
    const int k = row_k[r];
    const V last_t = simd::Load<V>(st[bLastT] + k), last_r = simd::Load<V>(st[bLastR] + k);
    // A chain that blended no pixel of the row is skipped (it would add nothing).
    const V raw_t = s.op * G, raw_r = s.rop * G;
    const V at = simd::Min(raw_t, simd::Splat<V>(kMaxAlpha));
    const V ar = simd::Min(raw_r, simd::Splat<V>(kMaxAlpha));
    const M vt = in & (jf < last_t) & (at >= kMinAlpha);
    const M vr = in & (jf < last_r) & (ar >= kMinAlpha);  // none without reflection (last_r = 0)
    if (!simd::Any(vt | vr)) continue;
    // Transmitted chain: recover T_j = T_{j+1} / (1 - a_j), then the gradients. x: G d loss / d a
    // where the alpha has slope, per chain.
    V x_t{}, x_r{};
    if (simd::Any(vt)) {
      const V inv_t = 1.0f / (1.0f - at);
      const V T_next = simd::Load<V>(st[bT] + k);
      const V T = simd::Select(vt, T_next * inv_t, T_next);
      simd::Store(st[bT] + k, T);
      const V wt = simd::Masked(vt, at * T);
      const V gt0 = simd::Load<V>(st[bGt0] + k), gt1 = simd::Load<V>(st[bGt1] + k),
              gt2 = simd::Load<V>(st[bGt2] + k);
      const V gW = simd::Load<V>(st[bGW] + k), gN = simd::Load<V>(st[bGN] + k);
      g_ct0 += wt * gt0;
      g_ct1 += wt * gt1;
      g_ct2 += wt * gt2;
      g_beta += wt * gW;
      g_z += wt * gN;
      const V qg = s.ct0 * gt0 + s.ct1 * gt1 + s.ct2 * gt2 + s.beta * gW + s.z * gN;  // q_i . g
      const V St = simd::Load<V>(st[bSt] + k);
      const V da_t = (qg - St) * T + simd::Load<V>(st[bTGA] + k) * inv_t;
      simd::Store(st[bSt] + k, simd::Select(vt, at * qg + (1.0f - at) * St, St));
      const M slope_t = vt & (raw_t < kMaxAlpha);  // the clamp at 0.99 has zero slope
      x_t = simd::Masked(slope_t, G * da_t);
      g_op += x_t;
    }
    if (refl && simd::Any(vr)) {  // the reflected chain
      const V inv_r = 1.0f / (1.0f - ar);
      const V Tr_next = simd::Load<V>(st[bTr] + k);
      const V Tr = simd::Select(vr, Tr_next * inv_r, Tr_next);
      simd::Store(st[bTr] + k, Tr);
      const V wr = simd::Masked(vr, ar * Tr);
      const V gr0 = simd::Load<V>(st[bGr0] + k), gr1 = simd::Load<V>(st[bGr1] + k),
              gr2 = simd::Load<V>(st[bGr2] + k);
      g_cr0 += wr * gr0;
      g_cr1 += wr * gr1;
      g_cr2 += wr * gr2;
      const V qg = s.cr0 * gr0 + s.cr1 * gr1 + s.cr2 * gr2;
      const V Sr = simd::Load<V>(st[bSr] + k);
      const V da_r = (qg - Sr) * Tr;
      simd::Store(st[bSr] + k, simd::Select(vr, ar * qg + (1.0f - ar) * Sr, Sr));
      const M slope_r = vr & (raw_r < kMaxAlpha);
      x_r = simd::Masked(slope_r, G * da_r);
      g_rop += x_r;
    }
    // Through G = exp(power) to the conic and the screen mean: d loss / d power =
    // G (o da_t + or da_r) (where the clamps have slope), the opacity gradients' terms times the
    // opacities.
    const V dpower = s.op * x_t + s.rop * x_r;
    sum_dp_dy += dpower * dy;
    sum_dp_dy2 += dpower * (dy * dy);
  }
  const V sum_dp = s.op * g_op + s.rop * g_rop;  // the rows' d loss / d power
  const V g_mx = s.ca * dx * sum_dp + s.cb * sum_dp_dy;
  const V g_my = s.cb * dx * sum_dp + s.cc * sum_dp_dy;
  const V g_ca = -0.5f * dx * dx * sum_dp;
  const V g_cb = -dx * sum_dp_dy;
  const V g_cc = -0.5f * sum_dp_dy2;
  // In the order of GradField (the 16th vector pads).
  const V lanes[16] = {g_mx, g_my,  g_ca,  g_cb,  g_cc,  g_op,  g_rop, g_beta,
                       g_z,  g_ct0, g_ct1, g_ct2, g_cr0, g_cr1, g_cr2, V{}};
  std::copy(lanes, lanes + 16, acc);
}

// An entry's gradient row `dst` (kGradStride floats) from GradientRows' per-lane sums.
template <class V>
void WriteGradients(const V acc[16], float* dst) {
  static_assert(kGradStride == 15, "one SumEach closes the entry");
  float sums[16];
  simd::SumEach(acc, sums);
  std::copy(sums, sums + kGradStride, dst);
}

}  // namespace

// Both passes walk a tile Gaussian by Gaussian (front to back, or back to front) and, for each,
// the tile rows its alpha box covers, 16 or 8 pixels at a time in vector registers, keeping every
// pixel's blending state in tile-local arrays. Per pixel, the order and the decisions are those
// of the per-pixel loop the header describes; masks replace its branches.
void RasterizeGaussians(const ProjectedGaussians& p, const TileBins& bins,
                        const GaussianRenderOptions& o, GaussianRender* out,
                        RasterScratch* scratch) {
  const int W = o.camera.width, H = o.camera.height;
  const size_t npix = static_cast<size_t>(W) * H;
  for (Image* im : {&out->color, &out->tran, &out->ref}) EnsureImage(im, W, H, 3);
  for (Image* im : {&out->weight, &out->depth, &out->alpha}) EnsureImage(im, W, H, 1);
  out->final_t.resize(npix);
  out->final_tr.resize(npix);
  out->depth_sum.resize(npix);
  out->last_t.resize(npix);
  out->last_r.resize(npix);
  out->entry_blended.resize(bins.ids.size());
  const int threads = omp_get_max_threads();
  EnsureScratch(scratch, threads, bins, kNumFields);
  const bool refl = o.reflection;
  const Image* bg_image = o.background_image;
  PackGaussians(p, &scratch->packed);
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
    buffer.resize(static_cast<size_t>(n) * kNumFields);
    const float* f = buffer.data();
    const int x0 = tx * kTileSize, y0 = ty * kTileSize;
    const int x_end = std::min(W, x0 + kTileSize), y_end = std::min(H, y0 + kTileSize);
    const TileLanes tl(x0, x_end - x0);

    const PixelArrays st(&scratch->pixel_state[thread], kForwardArrays);
    for (int k = 0; k < kTilePixels; ++k) {
      st[aT][k] = 1.0f;
      st[aTr][k] = refl ? 1.0f : -1.0f;  // without reflection the chain never blends
      for (int a : {aCt0, aCt1, aCt2, aCr0, aCr1, aCr2, aWs, aDs, aLastT, aLastR}) st[a][k] = 0.0f;
    }
    for (int j = 0; j < n; ++j) {
      // Every 32 Gaussians, stop the tile once all of its pixels are saturated.
      if ((j & 31) == 31) {
        int live = 0;
        for (int k = 0; k < kTilePixels; ++k) live |= (st[aT][k] > 0.0f) | (st[aTr][k] > 0.0f);
        if (live == 0) break;
      }
      if ((j & 31) == 0) GatherTile<kNumFields>(packed, ids, n, j, std::min(n, j + 32), &buffer);
      const Splat s(f + static_cast<size_t>(j) * kNumFields);
      if (!(s.min_power < 0.0f)) continue;  // too transparent to reach 1/255 anywhere
      int ya, yb;
      ReachedRange(s.my, s.ey, y0, y_end - 1, &ya, &yb);
      const ColumnWindow w = WindowFor(s.mx, s.ex, x0);
      float sum;
      if (w.half) {
        sum = simd::Sum(BlendRows<F8>(s, j, ya, yb, y0, w.first, tl, refl, st));
      } else {
        F16 weights_by_lane[1];
        WholeRows<1>(
            [&](auto lanes, int first, decltype(lanes)* out) {
              *out = BlendRows<decltype(lanes)>(s, j, ya, yb, y0, first, tl, refl, st);
            },
            weights_by_lane);
        sum = simd::Sum(weights_by_lane[0]);
      }
      if (weights != nullptr) weights[j] += sum;
      blended[j] = sum > 0.0f;  // a blended pixel's weight is at least kMinAlpha kMinTransmittance
    }
    // The outputs, a tile row at a time (the same operations per pixel as a scalar loop).
    const int cols = x_end - x0;
    for (int y = y0; y < y_end; ++y) {
      const int k = (y - y0) * kTileSize;
      const size_t pix = static_cast<size_t>(y) * W + x0;
      using raster_internal::LoadRow;
      using raster_internal::StoreRow;
      const F16 T = simd::Abs(simd::Load(st[aT] + k));  // negated where the chain terminated
      const F16 A = 1.0f - T;
      const F16 Ws = simd::Load(st[aWs] + k), Ds = simd::Load(st[aDs] + k);
      for (int c = 0; c < 3; ++c) {
        const F16 bg = raster_internal::BackgroundRow(bg_image, o.background, c, pix, cols);
        const F16 cr = simd::Load(st[aCr0 + c] + k);
        const F16 tran = simd::Load(st[aCt0 + c] + k) + T * bg;
        StoreRow(out->tran.plane(c) + pix, tran, cols);
        StoreRow(out->ref.plane(c) + pix, cr, cols);
        StoreRow(out->color.plane(c) + pix, tran + Ws * cr, cols);
      }
      StoreRow(out->weight.plane(0) + pix, Ws, cols);
      StoreRow(out->alpha.plane(0) + pix, A, cols);
      StoreRow(out->depth.plane(0) + pix, simd::Masked(A >= kMinDepthAlpha, Ds / A), cols);
      StoreRow(out->final_t.data() + pix, T, cols);
      StoreRow(out->final_tr.data() + pix, simd::Abs(simd::Load(st[aTr] + k)), cols);
      StoreRow(out->depth_sum.data() + pix, Ds, cols);
      raster_internal::StoreRowAsUint(out->last_t.data() + pix, simd::Load(st[aLastT] + k), cols);
      raster_internal::StoreRowAsUint(out->last_r.data() + pix, simd::Load(st[aLastR] + k), cols);
    }
  }
  if (o.record_contribution) {
    SumEntriesPerPrimitive(bins, entry_weight, p.size(), &out->contribution);
  } else {
    out->contribution.clear();
  }
}

void GaussianBackgroundGradient(const GaussianRender& r, const GaussianRenderGrad& g,
                                Image* d_background) {
  raster_internal::BackgroundGradientOf(r.final_t, r.color.width(), r.color.height(), g.color,
                                        g.tran, d_background);
}

void RasterizeGaussiansBackward(const ProjectedGaussians& p, const TileBins& bins,
                                const GaussianRenderOptions& o, const GaussianRender& r,
                                const GaussianRenderGrad& g, ProjectedGaussiansGrad* d,
                                RasterScratch* scratch) {
  const int W = o.camera.width, H = o.camera.height;
  const size_t num = p.size();
  const int threads = omp_get_max_threads();
  EnsureScratch(scratch, threads, bins, kNumFields);
  const bool refl = o.reflection;
  const Image* bg_image = o.background_image;
  if (scratch->packed_from != &p) {  // not the forward's projection (see RasterScratch)
    PackGaussians(p, &scratch->packed);
    scratch->packed_from = &p;
  }
  const float* packed = scratch->packed.data();

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
      const uint32_t* ids = bins.ids.data() + begin;
      std::vector<float>& buffer = scratch->tile_data[thread];
      float* tg = scratch->entry_grads.data() + static_cast<size_t>(begin) * kGradStride;
      const int x0 = tx * kTileSize, y0 = ty * kTileSize;
      const int x_end = std::min(W, x0 + kTileSize), y_end = std::min(H, y0 + kTileSize);
      const TileLanes tl(x0, x_end - x0);

      const PixelArrays st(&scratch->pixel_state[thread], kBackwardArrays);
      raster_internal::ClearBackwardState(st, kBackwardArrays, bSt, bSr + 1,
                                          x_end - x0 < kTileSize || y_end - y0 < kTileSize);
      // The upstream gradients folded onto the chains, a tile row at a time (the same operations
      // per pixel as a scalar loop; an output without a gradient reads as zeros and is added all
      // the same, as the scalar sums did).
      using raster_internal::LoadRow;
      using raster_internal::LoadRowOfUint;
      const int cols = x_end - x0;
      F16 last_max{};
      for (int y = y0; y < y_end; ++y) {
        const int k = (y - y0) * kTileSize;
        const size_t pix = static_cast<size_t>(y) * W + x0;
        const auto row_of = [&](const Image& im, int c) {
          return im.empty() ? F16{} : LoadRow(im.plane(c) + pix, cols);
        };
        const F16 Wv = LoadRow(r.weight.plane(0) + pix, cols);
        F16 gtc[3], w_grad{};
        for (int c = 0; c < 3; ++c) {
          const F16 gc = row_of(g.color, c);
          gtc[c] = gc + row_of(g.tran, c);
          simd::Store(st[bGr0 + c] + k, Wv * gc + row_of(g.ref, c));
          simd::Store(st[bGt0 + c] + k, gtc[c]);
          w_grad += gc * LoadRow(r.ref.plane(c) + pix, cols);
        }
        simd::Store(st[bGW] + k, w_grad + row_of(g.weight, 0));
        F16 a_grad = row_of(g.alpha, 0), n_grad{};
        const F16 T_final = LoadRow(r.final_t.data() + pix, cols);
        const F16 A = 1.0f - T_final;
        if (!g.depth.empty()) {
          const simd::MaskOf<F16> has_depth = A >= kMinDepthAlpha;
          const F16 gD = LoadRow(g.depth.plane(0) + pix, cols);
          n_grad = simd::Masked(has_depth, gD / A);
          a_grad = simd::Select(
              has_depth, a_grad - gD * LoadRow(r.depth_sum.data() + pix, cols) / (A * A), a_grad);
        }
        // The background and A terms share d T_N / d a_i = -T_N / (1 - a_i).
        const F16 bg_dot = raster_internal::BackgroundDot(bg_image, o.background, gtc, pix, cols);
        simd::Store(st[bTGA] + k, T_final * (a_grad - bg_dot));
        simd::Store(st[bGN] + k, n_grad);
        simd::Store(st[bT] + k, T_final);
        simd::Store(st[bTr] + k, LoadRow(r.final_tr.data() + pix, cols));
        const F16 lt = LoadRowOfUint(r.last_t.data() + pix, cols);
        const F16 lr = refl ? LoadRowOfUint(r.last_r.data() + pix, cols) : F16{};
        simd::Store(st[bLastT] + k, lt);
        simd::Store(st[bLastR] + k, lr);
        last_max = simd::Max(last_max, simd::Max(lt, lr));
      }
      const int max_last = raster_internal::LargestLane(last_max);
      GatherTile<kNumFields>(packed, ids, n, 0, max_last, &buffer);
      const float* f = buffer.data();
      const uint8_t* blended = r.entry_blended.data() + begin;
      for (int j = max_last - 1; j >= 0; --j) {
        float* dst = tg + static_cast<size_t>(j) * kGradStride;
        // Blended no pixel here (36% of the entries the backward reaches on a trained object) or
        // invisible everywhere: no gradient (the row is written).
        if (!blended[j]) {
          std::fill(dst, dst + kGradStride, 0.0f);
          continue;
        }
        const Splat s(f + static_cast<size_t>(j) * kNumFields);
        int ya, yb;
        ReachedRange(s.my, s.ey, y0, y_end - 1, &ya, &yb);
        const ColumnWindow w = WindowFor(s.mx, s.ex, x0);
        if (w.half) {
          F8 acc[16];
          GradientRows<F8>(s, j, ya, yb, y0, w.first, tl, refl, st, acc);
          WriteGradients(acc, dst);
        } else {
          F16 acc[16];
          WholeRows<16>(
              [&](auto lanes, int first, decltype(lanes)* out) {
                GradientRows<decltype(lanes)>(s, j, ya, yb, y0, first, tl, refl, st, out);
              },
              acc);
          WriteGradients(acc, dst);
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
    d->mean2d[2 * i] = 0.0f + s[gMx];
    d->mean2d[2 * i + 1] = 0.0f + s[gMy];
    d->conic[3 * i] = 0.0f + s[gCa];
    d->conic[3 * i + 1] = 0.0f + s[gCb];
    d->conic[3 * i + 2] = 0.0f + s[gCc];
    d->opacity[i] = 0.0f + s[gOp];
    d->ref_opacity[i] = 0.0f + s[gRefOp];
    d->beta[i] = 0.0f + s[gBeta];
    d->depth[i] = 0.0f + s[gZ];
    for (int c = 0; c < 3; ++c) {
      d->color_t[3 * i + c] = 0.0f + s[gCt0 + c];
      d->color_r[3 * i + c] = 0.0f + s[gCr0 + c];
    }
  }
}

}  // namespace mgsr
