#include "mgsr/render/tile_binning.h"

#include <glog/logging.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace mgsr {

TileRect TileRectFromBox(float cx, float cy, float rx, float ry, int tiles_x, int tiles_y) {
  // Clamped as floats, so a box far off screen converts in range.
  const auto tile = [](float edge, float add, int tiles) {
    return static_cast<uint16_t>(
        std::clamp(std::floor(edge / kTileSize) + add, 0.0f, static_cast<float>(tiles)));
  };
  TileRect r;
  r.x0 = tile(cx - rx, 0.0f, tiles_x);
  r.y0 = tile(cy - ry, 0.0f, tiles_y);
  r.x1 = tile(cx + rx, 1.0f, tiles_x);
  r.y1 = tile(cy + ry, 1.0f, tiles_y);
  return r;
}

TileEllipse TileEllipse::Of(float cx, float cy, float a_f, float b_f, float c_f, float r_f) {
  TileEllipse e;
  const double a = a_f, b = b_f, c = c_f;
  if (!(r_f < std::numeric_limits<float>::infinity()) || !(a > 0 && c > 0)) return e;
  // How close the form is to degenerate: rho = |b| / sqrt(ac) < 1 for an ellipse. Its value at
  // a point is at least (1 - rho) (a dx^2 + c dy^2), and its float rounding a few epsilons of
  // a dx^2 + c dy^2 + 2 |b dx dy| <= 2 (a dx^2 + c dy^2): relative to the value, at most 2 / (1 -
  // rho) times that. So r is widened by 1e-5 / (1 - rho), some 80 float epsilons' worth, and
  // nearly degenerate forms keep the whole rectangle.
  const double rho = std::abs(b) / std::sqrt(a * c);
  if (!(rho < 0.999)) return e;
  e.cx = cx;
  e.cy = cy;
  if (r_f < 0) {
    e.reach_x = e.reach_y = -1;
    return std::isfinite(cx) && std::isfinite(cy) ? e : TileEllipse();
  }
  const double r = r_f / (1.0 - 1e-5 / (1.0 - rho));
  const double det = a * c - b * b;
  // Across row dy the ellipse spans -b dy / a -+ sqrt(a r - det dy^2) / a.
  e.reach_x = static_cast<float>(std::sqrt(c * r / det));
  e.reach_y = static_cast<float>(std::sqrt(a * r / det));
  e.slope = static_cast<float>(-b / a);
  e.k0 = static_cast<float>(r / a);
  e.k1 = static_cast<float>(det / (a * a));
  e.left_row = static_cast<float>(b * std::sqrt(c * r / det) / c);
  // Out of float's range (or NaN from the caller's centre): the whole rectangle.
  for (const float v : {e.cx, e.cy, e.reach_x, e.reach_y, e.slope, e.k0, e.k1, e.left_row}) {
    if (!std::isfinite(v)) return TileEllipse();
  }
  return e;
}

void EllipseTileColumns(const TileEllipse& e, int ty, int width, int height, int* first,
                        int* last) {
  const int tiles_x = (width + kTileSize - 1) / kTileSize;
  *first = 0;
  *last = tiles_x;
  if (e.whole()) return;
  *last = 0;
  // The rows of pixel centres of tile row ty, relative to the centre and grown by the margin,
  // within the ellipse's own rows.
  constexpr float m = kTileEllipseMarginPx;
  const float y0 = std::max(ty * kTileSize + 0.5f - m - e.cy, -e.reach_y);
  const float y1 = std::min(std::min(height, (ty + 1) * kTileSize) - 0.5f + m - e.cy, e.reach_y);
  if (!(y0 <= y1)) return;
  // The left edge is convex in dy and the right edge concave, so over [y0, y1] each is extreme
  // at the ellipse's leftmost (rightmost) point if that row is inside, else at an end.
  const auto half = [&](float dy) { return std::sqrt(std::max(0.0f, e.k0 - e.k1 * dy * dy)); };
  const float h0 = half(y0), h1 = half(y1);
  const float x_min = y0 <= e.left_row && e.left_row <= y1
                          ? -e.reach_x
                          : std::min(e.slope * y0 - h0, e.slope * y1 - h1);
  const float x_max = y0 <= -e.left_row && -e.left_row <= y1
                          ? e.reach_x
                          : std::max(e.slope * y0 + h0, e.slope * y1 + h1);
  // Tile tx's pixel centres (grown) span [16 tx + 0.5 - m, 16 tx + 15.5 + m].
  const float lo = std::ceil((e.cx + x_min - (kTileSize - 0.5f) - m) / kTileSize);
  const float hi = std::floor((e.cx + x_max - 0.5f + m) / kTileSize) + 1;
  *first = static_cast<int>(std::clamp(lo, 0.0f, static_cast<float>(tiles_x)));
  *last = static_cast<int>(std::clamp(hi, 0.0f, static_cast<float>(tiles_x)));
}

namespace {

// The element range [begin, end) of chunk t of `chunks` over n elements.
inline void ChunkRange(size_t n, int chunks, int t, size_t* begin, size_t* end) {
  *begin = n * t / chunks;
  *end = n * (t + 1) / chunks;
}

// Turns per-chunk counts (`chunks` rows of `buckets`) into each (chunk, bucket)'s first place in
// bucket order, then chunk order: what keeps both counting sorts below stable. Writes each
// bucket's first place to bucket_start when given; returns the total.
uint32_t PlacesByBucketThenChunk(uint32_t* counts, int chunks, int buckets,
                                 uint32_t* bucket_start = nullptr) {
  uint32_t total = 0;
  for (int b = 0; b < buckets; ++b) {
    if (bucket_start != nullptr) bucket_start[b] = total;
    for (int t = 0; t < chunks; ++t) {
      uint32_t& c = counts[static_cast<size_t>(t) * buckets + b];
      const uint32_t count = c;
      c = total;
      total += count;
    }
  }
  return total;
}

// Stable LSD radix sort of (key, id) pairs by 32-bit key, 11 bits per pass, in `chunks`
// consecutive chunks in parallel: per pass, each chunk counts its digits, every (digit, chunk)
// gets its place in digit order and then chunk order, and each chunk moves its pairs there in
// order. So the result is the one stable order, whatever the chunk count. A pass whose digit is
// the same for every key (it would not move anything) is skipped.
void RadixSortByKey(int chunks, std::vector<uint32_t>* keys, std::vector<uint32_t>* ids,
                    std::vector<uint32_t>* tmp_keys, std::vector<uint32_t>* tmp_ids,
                    std::vector<uint32_t>* counts) {
  const size_t n = keys->size();
  tmp_keys->resize(n);
  tmp_ids->resize(n);
  constexpr int kBits = 11, kBuckets = 1 << kBits, kPasses = (32 + kBits - 1) / kBits;
  constexpr uint32_t kMask = kBuckets - 1;
  counts->resize(static_cast<size_t>(chunks) * kBuckets);
  if (n == 0) return;
  for (int pass = 0; pass < kPasses; ++pass) {
    const int shift = pass * kBits;
    // 1. Each chunk's digit counts (and whether any key's digit differs from the first key's).
    const uint32_t first_digit = ((*keys)[0] >> shift) & kMask;
    int differs = 0;
#pragma omp parallel for schedule(static) num_threads(chunks) reduction(| : differs)
    for (int t = 0; t < chunks; ++t) {
      uint32_t* count = counts->data() + static_cast<size_t>(t) * kBuckets;
      std::fill(count, count + kBuckets, 0u);
      size_t begin, end;
      ChunkRange(n, chunks, t, &begin, &end);
      const uint32_t* k_in = keys->data();
      for (size_t i = begin; i < end; ++i) {
        const uint32_t d = (k_in[i] >> shift) & kMask;
        ++count[d];
        differs |= d != first_digit;
      }
    }
    if (!differs) continue;
    // 2. Places: digit by digit, chunk by chunk.
    PlacesByBucketThenChunk(counts->data(), chunks, kBuckets);
    // 3. Each chunk moves its pairs, in order.
#pragma omp parallel for schedule(static) num_threads(chunks)
    for (int t = 0; t < chunks; ++t) {
      uint32_t* place = counts->data() + static_cast<size_t>(t) * kBuckets;
      size_t begin, end;
      ChunkRange(n, chunks, t, &begin, &end);
      const uint32_t* k_in = keys->data();
      const uint32_t* id_in = ids->data();
      uint32_t* k_out = tmp_keys->data();
      uint32_t* id_out = tmp_ids->data();
      for (size_t i = begin; i < end; ++i) {
        const uint32_t at = place[(k_in[i] >> shift) & kMask]++;
        k_out[at] = k_in[i];
        id_out[at] = id_in[i];
      }
    }
    keys->swap(*tmp_keys);
    ids->swap(*tmp_ids);
  }
}

// Calls tile(tx, ty) for every tile of rectangle `r` that primitive `id` is binned to: all of them,
// or where the rectangle is at least kMinEllipseBinningWidth tiles wide and the primitive has
// shapes, per tile row the hull of the columns its shapes reach.
template <class Tile>
inline void ForEachBinnedTile(const TileEllipse* shapes, int per_primitive, uint32_t id,
                              const TileRect& r, int width, int height, const Tile& tile) {
  const bool fitted = shapes != nullptr && r.x1 - r.x0 >= kMinEllipseBinningWidth;
  const TileEllipse* e = fitted ? shapes + static_cast<size_t>(id) * per_primitive : nullptr;
  for (int ty = r.y0; ty < r.y1; ++ty) {
    int x0 = r.x0, x1 = r.x1;
    if (fitted) {
      int lo = r.x1, hi = r.x0;
      for (int k = 0; k < per_primitive; ++k) {
        int first, last;
        EllipseTileColumns(e[k], ty, width, height, &first, &last);
        if (first >= last) continue;
        lo = std::min(lo, first);
        hi = std::max(hi, last);
      }
      x0 = std::max<int>(x0, lo);
      x1 = std::min<int>(x1, hi);
    }
    for (int tx = x0; tx < x1; ++tx) tile(tx, ty);
  }
}

}  // namespace

void BinPrimitives(const std::vector<TileRect>& rects, const float* depths, int width, int height,
                   TileBins* bins, const TileEllipse* shapes, int per_primitive) {
  bins->tiles_x = (width + kTileSize - 1) / kTileSize;
  bins->tiles_y = (height + kTileSize - 1) / kTileSize;
  CHECK(bins->tiles_x <= kMaxTiles && bins->tiles_y <= kMaxTiles)
      << "an image of " << width << " x " << height << " pixels has more tiles than TileRect holds";
  const int num_tiles = bins->num_tiles();
  // Chunks, not threads, own the work of each parallel step below: a team can be smaller than
  // omp_get_max_threads() says (inside a caller's parallel region it has one thread), and every
  // chunk must still be done. Any chunk count gives the same lists.
  const int chunks = omp_get_max_threads();
  // 1. The drawn primitives in depth order (ties by id): one radix sort instead of a sort per tile.
  //    Positive floats order like their bit patterns. Each chunk of the ids writes its drawn ones
  //    at its own start, and the chunks then close up in order.
  const size_t num = rects.size();
  bins->order_keys.resize(num);
  bins->order.resize(num);
  bins->chunk_counts.assign(static_cast<size_t>(chunks), 0);
#pragma omp parallel for schedule(static) num_threads(chunks)
  for (int t = 0; t < chunks; ++t) {
    size_t begin, end;
    ChunkRange(num, chunks, t, &begin, &end);
    size_t at = begin;
    for (size_t i = begin; i < end; ++i) {
      if (rects[i].empty()) continue;
      uint32_t bits;
      std::memcpy(&bits, &depths[i], 4);
      bins->order_keys[at] = bits;
      bins->order[at++] = static_cast<uint32_t>(i);
    }
    bins->chunk_counts[t] = static_cast<uint32_t>(at - begin);
  }
  size_t drawn = 0;
  for (int t = 0; t < chunks; ++t) {
    size_t begin, end;
    ChunkRange(num, chunks, t, &begin, &end);
    const size_t c = bins->chunk_counts[t];
    if (c > 0 && drawn != begin) {  // (no move, and no pointer into an empty vector, otherwise)
      std::memmove(bins->order_keys.data() + drawn, bins->order_keys.data() + begin, c * 4);
      std::memmove(bins->order.data() + drawn, bins->order.data() + begin, c * 4);
    }
    drawn += c;
  }
  bins->order_keys.resize(drawn);
  bins->order.resize(drawn);
  RadixSortByKey(chunks, &bins->order_keys, &bins->order, &bins->tmp_keys, &bins->tmp_ids,
                 &bins->chunk_counts);
  const size_t n = bins->order.size();
  bins->chunk_counts.assign(static_cast<size_t>(chunks) * num_tiles, 0);
  bins->tile_start.assign(num_tiles + 1, 0);

  // 2. Per-chunk tile histograms over consecutive chunks of the depth order, which also copies the
  //    rectangles into that order: the scatter below then reads them in sequence, not at random.
  bins->sorted_rects.resize(n);
#pragma omp parallel for schedule(static) num_threads(chunks)
  for (int t = 0; t < chunks; ++t) {
    uint32_t* counts = bins->chunk_counts.data() + static_cast<size_t>(t) * num_tiles;
    size_t begin, end;
    ChunkRange(n, chunks, t, &begin, &end);
    for (size_t q = begin; q < end; ++q) {
      const uint32_t id = bins->order[q];
      const TileRect r = rects[id];
      bins->sorted_rects[q] = r;
      ForEachBinnedTile(shapes, per_primitive, id, r, width, height,
                        [&](int tx, int ty) { ++counts[ty * bins->tiles_x + tx]; });
    }
  }
  // 3. Offsets: within a tile, chunk t's (deeper) entries follow those of chunks < t, so every
  //    tile list comes out front to back.
  const uint32_t total = PlacesByBucketThenChunk(bins->chunk_counts.data(), chunks, num_tiles,
                                                 bins->tile_start.data());
  bins->tile_start[num_tiles] = total;
  bins->ids.resize(total);
#pragma omp parallel for schedule(static) num_threads(chunks)
  for (int t = 0; t < chunks; ++t) {
    uint32_t* offsets = bins->chunk_counts.data() + static_cast<size_t>(t) * num_tiles;
    size_t begin, end;
    ChunkRange(n, chunks, t, &begin, &end);
    for (size_t q = begin; q < end; ++q) {
      const uint32_t id = bins->order[q];
      const TileRect& r = bins->sorted_rects[q];
      ForEachBinnedTile(shapes, per_primitive, id, r, width, height, [&](int tx, int ty) {
        bins->ids[offsets[ty * bins->tiles_x + tx]++] = id;
      });
    }
  }
  // 4. The largest tiles first.
  bins->tile_order.resize(num_tiles);
  for (int tile = 0; tile < num_tiles; ++tile) bins->tile_order[tile] = tile;
  const std::vector<uint32_t>& start = bins->tile_start;
  std::sort(bins->tile_order.begin(), bins->tile_order.end(), [&start](int a, int b) {
    const uint32_t na = start[a + 1] - start[a], nb = start[b + 1] - start[b];
    return na != nb ? na > nb : a < b;
  });
}

}  // namespace mgsr
