// Per-thread scratch memory shared by the tile rasterizers, reused between calls so that a warm
// renderer does not allocate, and the deterministic reduction of per-tile gradients.
#pragma once

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "mgsr/core/image.h"
#include "mgsr/render/simd16.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr {

struct RasterScratch {
  // Per primitive, what the pixel loops read about it, in one row (both rasterizers).
  std::vector<float> packed;
  // The projection `packed` was packed from by the last forward pass, which the backward reuses
  // when it is handed the same one (the renderers' pairing: a backward follows the forward of the
  // same projection, whose render it already reads); null before any forward.
  const void* packed_from = nullptr;
  // d c / d M of the surfels' low-pass offsets (backward, area-preserving filter).
  std::vector<float> low_pass;
  std::vector<std::vector<float>> pixel_state;  // per thread: pixel state of the current tile
  std::vector<std::vector<float>> tile_data;  // per thread: gathered primitives of the current tile
  std::vector<float> entry_grads;             // per tile entry: gradient fields (stride floats)
  std::vector<uint32_t> tile_used;            // per tile: entries [0, used) hold gradients
  std::vector<float> per_primitive;           // per primitive: reduced gradient fields
};

// Helpers shared by the two tile rasterizers.
namespace raster_internal {

constexpr int kTilePixels = kTileSize * kTileSize;
// The most per-pixel arrays a pass carves out of a thread's pixel state (PixelArrays).
constexpr int kMaxPixelArrays = 32;

// Sizes every thread's tile buffer for the largest tile of `bins` (`fields` floats per entry)
// and its pixel state for the most arrays any pass uses, before the parallel loop. Which thread
// draws which tile depends on scheduling, so buffers grown inside the loop allocated at times
// that varied from run to run: a steady iteration now and then allocated once (a thread that,
// starved on a loaded machine, drew its first non-empty backward tile late grew its pixel state
// from the forward's arrays to the backward's). Sized here, the tile buffers grow only when the
// largest tile does, with headroom, and the pixel state never after the first call.
inline void EnsureScratch(RasterScratch* s, int threads, const TileBins& bins, int fields) {
  if (static_cast<int>(s->tile_data.size()) < threads) {
    s->tile_data.resize(threads);
    s->pixel_state.resize(threads);
  }
  for (std::vector<float>& state : s->pixel_state)
    state.reserve(static_cast<size_t>(kMaxPixelArrays) * kTilePixels);
  uint32_t largest = 0;
  for (int t = 0; t < bins.num_tiles(); ++t)
    largest = std::max(largest, bins.tile_start[t + 1] - bins.tile_start[t]);
  const size_t need = static_cast<size_t>(largest) * fields;
  for (std::vector<float>& buffer : s->tile_data)
    if (buffer.capacity() < need) buffer.reserve(need + need / 2);
}

// Copies the packed rows (kFields floats each) of a tile's primitives [begin, end) of its n into
// one contiguous buffer (sized for all n) before the pixel loops read them: the independent loads
// overlap their cache misses, which the compute-heavy pixel loop would otherwise serialise. The
// passes gather only the entries they reach: the forward 32 at a time, as it stops once the tile
// is saturated; the backward those in front of the last blended one.
template <int kFields>
inline void GatherTile(const float* packed, const uint32_t* ids, int n, int begin, int end,
                       std::vector<float>* buffer) {
  buffer->resize(static_cast<size_t>(n) * kFields);
  float* out = buffer->data();
  for (int j = begin; j < end; ++j) {
    std::memcpy(out + static_cast<size_t>(j) * kFields,
                packed + static_cast<size_t>(ids[j]) * kFields, kFields * sizeof(float));
  }
}

inline void EnsureImage(Image* im, int w, int h, int c) {
  if (im->width() != w || im->height() != h || im->channels() != c) *im = Image(w, h, c);
}

// A lower bound of log(min_alpha / o) for an opacity o in [min_alpha, 1]: the exponent below which
// o G, G = exp(exponent), stays under min_alpha (the 3DGS backward's per-chain row filter). No
// logarithm: log2(o) is at most the float's bits read as a number (exponent and mantissa fraction)
// plus 0.0861 (the largest log2(1 + f) - f on [0, 1)); margins cover the bits' conversion and the
// exponent's rounding.
inline float FaintPowerBound(float o, float log_min_alpha) {
  uint32_t bits;
  std::memcpy(&bits, &o, sizeof(bits));
  const float log2_upper = static_cast<float>(bits) * (1.0f / 8388608.0f) - 127.0f + 0.0862f;
  return log_min_alpha - 0.6931472f * log2_upper - 1e-4f;
}

// Whether the pixel centre i + 0.5 of row or column i lies within `half_width` of `m`: the pixel
// loops' own test, in the same float arithmetic.
inline bool CentreReached(float m, float half_width, int i) {
  return std::abs((static_cast<float>(i) + 0.5f) - m) <= half_width;
}

// The rows (or columns) [*lo, *hi] of [first, last] whose centres CentreReached accepts, exactly
// (empty: *lo > *hi): a primitive's box rows in a tile, so the pixel loops need no row test of
// their own. An estimate, corrected by the exact test: the accepted indices are contiguous, as the
// rounded |i + 0.5 - m| never decreases away from m. (With a row of slack on each side, as before
// 2026-11-27, a splat's box had about 8 rows of which 5 passed, and the 3DGS backward took every
// box row's exponent.)
inline void ReachedRange(float m, float half_width, int first, int last, int* lo, int* hi) {
  const float lo_f = std::clamp(std::ceil(m - half_width - 0.5f), first - 1.0f, last + 1.0f);
  const float hi_f = std::clamp(std::floor(m + half_width - 0.5f), first - 1.0f, last + 1.0f);
  int a = static_cast<int>(lo_f), b = static_cast<int>(hi_f);
  while (a > first && CentreReached(m, half_width, a - 1)) --a;
  while (a <= last && !CentreReached(m, half_width, a)) ++a;
  while (b < last && CentreReached(m, half_width, b + 1)) ++b;
  while (b >= first && !CentreReached(m, half_width, b)) --b;
  *lo = std::max(a, first);
  *hi = std::min(b, last);
}

// Which columns of a tile row the pixel loops process for one primitive that reaches only pixels
// whose centre x + 0.5 lies within `half_width` of `mx` (the lanes' own test, CentreReached): a
// footprint of at most 8 columns of the tile takes one 8-lane vector starting at `first`,
// anything wider the whole 16-lane row. Per pixel nothing changes; a trained object's splats are
// mostly 3-8 px wide, so this halves the lanes that compute nothing.
struct ColumnWindow {
  int first = 0;
  bool half = false;
};
inline ColumnWindow WindowFor(float mx, float half_width, int x0) {
  int lo, hi;
  ReachedRange(mx, half_width, x0, x0 + kTileSize - 1, &lo, &hi);
  lo -= x0;
  hi -= x0;
  if (hi - lo >= 8) return {};
  return {std::clamp(lo, 0, kTileSize - 8), true};
}

// One primitive's pass over whole 16-column tile rows. `lanes(tag, first, out)` runs the pass over
// the columns [first, first + lanes of decltype(tag)) and writes its N per-lane results (blend
// weights, gradient sums) to `out`. Where the build has AVX-512 that is one 16-lane pass; otherwise
// two 8-lane passes, over columns 0-7 and 8-15, whose results are joined lane for lane. Pixels are
// independent and every result is per lane, so the joined results are the 16-lane pass's to the
// bit; but each half skips its own empty rows, and keeps half as many registers live (AVX2 has 16
// vector registers and a 16-lane vector takes two of them).
template <int N, class Lanes>
inline void WholeRows(Lanes lanes, simd::F16 out[N]) {
#if MGSR_SIMD_NATIVE16
  lanes(simd::F16{}, 0, out);
#else
  simd::F8 lo[N], hi[N];
  lanes(simd::F8{}, 0, lo);
  lanes(simd::F8{}, 8, hi);
  for (int i = 0; i < N; ++i) out[i] = {lo[i], hi[i]};
#endif
}

// The pixel lanes of a tile: centres and "inside the image" masks at both widths.
struct TileLanes {
  simd::F16 px16;
  simd::MaskOf<simd::F16> ok16;
  int x0 = 0, valid = 0;
  TileLanes(int tile_x0, int valid_columns) : x0(tile_x0), valid(valid_columns) {
    px16 = simd::Lanes<simd::F16>() + (x0 + 0.5f);
    ok16 = simd::Lanes<simd::F16>() < static_cast<float>(valid);
  }
  template <class V>
  V Px(int first) const;
  template <class V>
  simd::MaskOf<V> Ok(int first) const;
};
template <>
inline simd::F16 TileLanes::Px<simd::F16>(int) const {
  return px16;
}
template <>
inline simd::MaskOf<simd::F16> TileLanes::Ok<simd::F16>(int) const {
  return ok16;
}
template <>
inline simd::F8 TileLanes::Px<simd::F8>(int first) const {
  return simd::Lanes<simd::F8>() + (x0 + first + 0.5f);
}
template <>
inline simd::MaskOf<simd::F8> TileLanes::Ok<simd::F8>(int first) const {
  return simd::Lanes<simd::F8>() < static_cast<float>(valid - first);
}

// The first `n` (1..16) floats at p as a 16-lane row and back: a tile row's pixels in an image
// row, where a tile cut by the image's right edge has fewer than 16 (lanes past n read as 0 and
// are not written).
inline simd::F16 LoadRow(const float* p, int n) {
  if (n == kTileSize) return simd::Load<simd::F16>(p);
  simd::F16 v{};
  std::memcpy(&v, p, sizeof(float) * n);
  return v;
}
inline void StoreRow(float* p, simd::F16 v, int n) {
  if (n == kTileSize) return simd::Store(p, v);
  std::memcpy(p, &v, sizeof(float) * n);
}
// Unsigned integers (below 2^24, so exact as floats) to and from such rows.
inline simd::F16 LoadRowOfUint(const uint32_t* p, int n) {
  simd::U16 u{};
  std::memcpy(&u, p, sizeof(uint32_t) * n);
  return simd::ToFloat(u);
}
inline void StoreRowAsUint(uint32_t* p, simd::F16 v, int n) {
  const simd::U16 u = simd::ToUint(v);
  std::memcpy(p, &u, sizeof(uint32_t) * n);
}
// Channel c of the background behind a tile row: the per-pixel image where there is one, else
// the constant colour.
inline simd::F16 BackgroundRow(const Image* image, const float background[3], int c, size_t pix,
                               int n) {
  return image != nullptr ? LoadRow(image->plane(c) + pix, n) : simd::Splat(background[c]);
}
// sum_c background_c g_c over a tile row (the background's share of d loss / d alpha).
inline simd::F16 BackgroundDot(const Image* image, const float background[3], const simd::F16 g[3],
                               size_t pix, int n) {
  simd::F16 dot{};
  for (int c = 0; c < 3; ++c) dot += BackgroundRow(image, background, c, pix, n) * g[c];
  return dot;
}

// The largest lane of a row of such integers (a tile's largest last-blended count).
inline int LargestLane(simd::F16 v) {
  int largest = 0;
  for (int l = 0; l < kTileSize; ++l) largest = std::max(largest, static_cast<int>(v[l]));
  return largest;
}

// Per-pixel arrays of a tile (index k = row * 16 + column) carved out of one per-thread buffer,
// without allocating per tile.
class PixelArrays {
 public:
  PixelArrays(std::vector<float>* buffer, int count) {
    buffer->resize(static_cast<size_t>(count) * kTilePixels);
    for (int i = 0; i < count && i < kMaxPixelArrays; ++i)
      arrays_[i] = buffer->data() + static_cast<size_t>(i) * kTilePixels;
  }
  float* operator[](int i) const { return arrays_[i]; }

 private:
  float* arrays_[kMaxPixelArrays] = {};
};

// Clears a tile's backward pixel state before its per-pixel set-up. Arrays [acc_begin, acc_end)
// (the "behind" accumulators, which the set-up does not write) start at zero; the set-up writes
// every other array the pixel loops read at every pixel inside the image, so those are cleared
// only when the image edge cuts the tile: the vector lanes still read the outside pixels (masked),
// and those must hold finite values.
inline void ClearBackwardState(const PixelArrays& st, int count, int acc_begin, int acc_end,
                               bool cut_by_edge) {
  const int begin = cut_by_edge ? 0 : acc_begin, end = cut_by_edge ? count : acc_end;
  for (int a = begin; a < end; ++a) std::fill(st[a], st[a] + kTilePixels, 0.0f);
}

// d loss / d (each pixel's background) for a render whose colour outputs hold
// T_N * background: T_N times the sum of those outputs' gradients (an empty image counts 0).
inline void BackgroundGradientOf(const std::vector<float>& final_t, int width, int height,
                                 const Image& grad_a, const Image& grad_b, Image* d_background) {
  EnsureImage(d_background, width, height, 3);
  const size_t np = static_cast<size_t>(width) * height;
  for (int c = 0; c < 3; ++c) {
    float* out = d_background->plane(c);
    const float* ga = grad_a.empty() ? nullptr : grad_a.plane(c);
    const float* gb = grad_b.empty() ? nullptr : grad_b.plane(c);
    for (size_t i = 0; i < np; ++i)
      out[i] = final_t[i] * ((ga != nullptr ? ga[i] : 0.0f) + (gb != nullptr ? gb[i] : 0.0f));
  }
}

// Per-primitive sums of per-entry values (entries in bins order, one per tile list slot), in
// entry order whatever the thread count: the contribution a forward pass records.
inline void SumEntriesPerPrimitive(const TileBins& bins, const std::vector<float>& entry,
                                   size_t num, std::vector<float>* out) {
  out->assign(num, 0.0f);
  for (size_t k = 0; k < entry.size(); ++k) (*out)[bins.ids[k]] += entry[k];
}

// dst[q] += src[q] for a row of `stride` floats, in 8-float vectors; where the row is not a whole
// number of them the last one overlaps the one before (all are loaded before any is stored, so the
// shared floats get the same sum twice).
template <int stride>
inline void AddRow(float* __restrict dst, const float* __restrict src) {
  if constexpr (stride >= 8) {
    using simd::F8;
    constexpr int kParts = (stride + 7) / 8;
    F8 sum[kParts];
    for (int c = 0; c < kParts; ++c) {
      const int o = std::min(8 * c, stride - 8);
      sum[c] = simd::Load<F8>(dst + o) + simd::Load<F8>(src + o);
    }
    for (int c = 0; c < kParts; ++c) simd::Store(dst + std::min(8 * c, stride - 8), sum[c]);
  } else {
    for (int q = 0; q < stride; ++q) dst[q] += src[q];
  }
}

}  // namespace raster_internal

// Sums the per-entry gradients of every tile into per-primitive rows (N x stride), in tile and
// entry order whatever the thread count, so backward passes are bitwise reproducible. The
// primitives are split into one range per thread, each summed by one thread scanning the entry
// list once (ranges, not threads, are the loop: a team smaller than omp_get_max_threads() says
// still sums every range).
//
// The scan first lists, without a branch, a chunk's entries of its own range, then adds their
// rows, fetching the destination rows a few entries ahead. The destination rows are in random
// order and mostly outside the core's cache; with a branch per entry (half of them taken, at
// random) each mispredict emptied the pipeline and every row's miss stood alone: the first add of
// a row took over half the reduction's samples (`perf annotate`, 100k benchmark).
template <int stride>
inline void ReduceEntryGradients(const TileBins& bins, const std::vector<uint32_t>& tile_used,
                                 const std::vector<float>& entry_grads, size_t num,
                                 std::vector<float>* out) {
  out->resize(num * stride);
  const int ranges = omp_get_max_threads();
  constexpr int kChunk = 256, kAhead = 8;
#pragma omp parallel for schedule(static) num_threads(ranges)
  for (int t = 0; t < ranges; ++t) {
    const uint32_t lo = static_cast<uint32_t>(num * t / ranges),
                   hi = static_cast<uint32_t>(num * (t + 1) / ranges);
    float* __restrict const sums = out->data();
    const float* __restrict const rows = entry_grads.data();
    const uint32_t* const ids = bins.ids.data();
    // Each thread zeroes the rows it sums into (a serial fill left the others waiting).
    std::fill(sums + static_cast<size_t>(lo) * stride, sums + static_cast<size_t>(hi) * stride,
              0.0f);
    uint32_t own[kChunk];
    for (int tile = 0; tile < bins.num_tiles(); ++tile) {
      const uint32_t begin = bins.tile_start[tile], end = begin + tile_used[tile];
      for (uint32_t c0 = begin; c0 < end; c0 += kChunk) {
        const uint32_t c1 = std::min(end, c0 + kChunk);
        int count = 0;
        for (uint32_t e = c0; e < c1; ++e) {
          own[count] = e;
          count += ids[e] - lo < hi - lo;  // (unsigned: lo <= id < hi)
        }
        for (int k = 0; k < count; ++k) {
          if (k + kAhead < count)
            __builtin_prefetch(sums + static_cast<size_t>(ids[own[k + kAhead]]) * stride);
          const uint32_t e = own[k];
          const float* src = rows + static_cast<size_t>(e) * stride;
          float* dst = sums + static_cast<size_t>(ids[e]) * stride;
          raster_internal::AddRow<stride>(dst, src);
        }
      }
    }
  }
}

}  // namespace mgsr
