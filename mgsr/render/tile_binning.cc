#include "mgsr/render/tile_binning.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace mgsr {

TileRect TileRectFromBox(float cx, float cy, float rx, float ry, int tiles_x, int tiles_y) {
  TileRect r;
  r.x0 = std::clamp(static_cast<int>(std::floor((cx - rx) / kTileSize)), 0, tiles_x);
  r.y0 = std::clamp(static_cast<int>(std::floor((cy - ry) / kTileSize)), 0, tiles_y);
  r.x1 = std::clamp(static_cast<int>(std::floor((cx + rx) / kTileSize)) + 1, 0, tiles_x);
  r.y1 = std::clamp(static_cast<int>(std::floor((cy + ry) / kTileSize)) + 1, 0, tiles_y);
  return r;
}

namespace {

// Stable LSD radix sort of (key, id) pairs by 32-bit key, 11 bits per pass. The three passes'
// histograms come from one read of the keys, and a pass whose digit is the same for every key
// (it would not move anything) is skipped.
void RadixSortByKey(std::vector<uint32_t>* keys, std::vector<uint32_t>* ids,
                    std::vector<uint32_t>* tmp_keys, std::vector<uint32_t>* tmp_ids) {
  const size_t n = keys->size();
  tmp_keys->resize(n);
  tmp_ids->resize(n);
  constexpr int kBits = 11, kBuckets = 1 << kBits, kPasses = (32 + kBits - 1) / kBits;
  constexpr uint32_t kMask = kBuckets - 1;
  static_assert(kPasses == 3, "the histogram loop below counts three digits");
  uint32_t count[kPasses][kBuckets] = {};
  for (const uint32_t k : *keys) {
    ++count[0][k & kMask];
    ++count[1][(k >> kBits) & kMask];
    ++count[2][(k >> (2 * kBits)) & kMask];
  }
  for (int pass = 0; pass < kPasses; ++pass) {
    const int shift = pass * kBits;
    uint32_t* start = count[pass];
    if (n == 0 || start[((*keys)[0] >> shift) & kMask] == n) continue;  // one digit: no move
    uint32_t sum = 0;
    for (int b = 0; b < kBuckets; ++b) {
      const uint32_t v = start[b];
      start[b] = sum;
      sum += v;
    }
    const uint32_t* k_in = keys->data();
    const uint32_t* id_in = ids->data();
    uint32_t* k_out = tmp_keys->data();
    uint32_t* id_out = tmp_ids->data();
    for (size_t i = 0; i < n; ++i) {
      const uint32_t at = start[(k_in[i] >> shift) & kMask]++;
      k_out[at] = k_in[i];
      id_out[at] = id_in[i];
    }
    keys->swap(*tmp_keys);
    ids->swap(*tmp_ids);
  }
}

}  // namespace

void BinPrimitives(const std::vector<TileRect>& rects, const float* depths, int width, int height,
                   TileBins* bins) {
  bins->tiles_x = (width + kTileSize - 1) / kTileSize;
  bins->tiles_y = (height + kTileSize - 1) / kTileSize;
  const int num_tiles = bins->num_tiles();
  // 1. The drawn primitives in depth order (ties by id): one radix sort instead of a sort per tile.
  //    Positive floats order like their bit patterns.
  bins->order_keys.clear();
  bins->order.clear();
  for (size_t i = 0; i < rects.size(); ++i) {
    if (rects[i].empty()) continue;
    uint32_t bits;
    std::memcpy(&bits, &depths[i], 4);
    bins->order_keys.push_back(bits);
    bins->order.push_back(static_cast<uint32_t>(i));
  }
  RadixSortByKey(&bins->order_keys, &bins->order, &bins->tmp_keys, &bins->tmp_ids);
  const int n = static_cast<int>(bins->order.size());
  // One chunk of the depth order per thread. Chunks, not threads, own the counts: a team can be
  // smaller than omp_get_max_threads() says (inside a caller's parallel region it has one
  // thread), and every chunk must still be counted. Any chunk count gives the same lists.
  const int chunks = omp_get_max_threads();
  bins->chunk_counts.assign(static_cast<size_t>(chunks) * num_tiles, 0);
  bins->tile_start.assign(num_tiles + 1, 0);

  // 2. Per-chunk tile histograms over consecutive chunks of the depth order.
#pragma omp parallel for schedule(static) num_threads(chunks)
  for (int t = 0; t < chunks; ++t) {
    uint32_t* counts = bins->chunk_counts.data() + static_cast<size_t>(t) * num_tiles;
    const int begin = static_cast<int>(static_cast<int64_t>(n) * t / chunks);
    const int end = static_cast<int>(static_cast<int64_t>(n) * (t + 1) / chunks);
    for (int q = begin; q < end; ++q) {
      const TileRect& r = rects[bins->order[q]];
      for (int ty = r.y0; ty < r.y1; ++ty) {
        for (int tx = r.x0; tx < r.x1; ++tx) ++counts[ty * bins->tiles_x + tx];
      }
    }
  }
  // 3. Offsets: within a tile, chunk t's (deeper) entries follow those of chunks < t, so every
  //    tile list comes out front to back.
  uint32_t total = 0;
  for (int tile = 0; tile < num_tiles; ++tile) {
    bins->tile_start[tile] = total;
    for (int t = 0; t < chunks; ++t) {
      uint32_t& c = bins->chunk_counts[static_cast<size_t>(t) * num_tiles + tile];
      const uint32_t count = c;
      c = total;
      total += count;
    }
  }
  bins->tile_start[num_tiles] = total;
  bins->ids.resize(total);
#pragma omp parallel for schedule(static) num_threads(chunks)
  for (int t = 0; t < chunks; ++t) {
    uint32_t* offsets = bins->chunk_counts.data() + static_cast<size_t>(t) * num_tiles;
    const int begin = static_cast<int>(static_cast<int64_t>(n) * t / chunks);
    const int end = static_cast<int>(static_cast<int64_t>(n) * (t + 1) / chunks);
    for (int q = begin; q < end; ++q) {
      const uint32_t id = bins->order[q];
      const TileRect& r = rects[id];
      for (int ty = r.y0; ty < r.y1; ++ty) {
        for (int tx = r.x0; tx < r.x1; ++tx) bins->ids[offsets[ty * bins->tiles_x + tx]++] = id;
      }
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
