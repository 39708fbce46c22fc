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

void BinPrimitives(const std::vector<TileRect>& rects, const float* depths, int width, int height,
                   TileBins* bins) {
  bins->tiles_x = (width + kTileSize - 1) / kTileSize;
  bins->tiles_y = (height + kTileSize - 1) / kTileSize;
  const int num_tiles = bins->num_tiles();
  const int n = static_cast<int>(rects.size());
  const int threads = omp_get_max_threads();
  bins->thread_counts.assign(static_cast<size_t>(threads) * num_tiles, 0);
  bins->tile_start.assign(num_tiles + 1, 0);

  // Pass 1: per-thread histograms over a static split of the primitives.
#pragma omp parallel num_threads(threads)
  {
    const int t = omp_get_thread_num();
    uint32_t* counts = bins->thread_counts.data() + static_cast<size_t>(t) * num_tiles;
    const int begin = static_cast<int>(static_cast<int64_t>(n) * t / threads);
    const int end = static_cast<int>(static_cast<int64_t>(n) * (t + 1) / threads);
    for (int i = begin; i < end; ++i) {
      const TileRect& r = rects[i];
      if (r.empty()) continue;
      for (int ty = r.y0; ty < r.y1; ++ty) {
        for (int tx = r.x0; tx < r.x1; ++tx) ++counts[ty * bins->tiles_x + tx];
      }
    }
  }
  // Exclusive prefix over (tile, thread): thread t's entries of a tile follow threads < t.
  uint32_t total = 0;
  for (int tile = 0; tile < num_tiles; ++tile) {
    bins->tile_start[tile] = total;
    for (int t = 0; t < threads; ++t) {
      uint32_t& c = bins->thread_counts[static_cast<size_t>(t) * num_tiles + tile];
      const uint32_t count = c;
      c = total;  // becomes this thread's write offset
      total += count;
    }
  }
  bins->tile_start[num_tiles] = total;
  bins->keys.resize(total);

  // Pass 2: fill (depth bits << 32 | id); positive floats order like their bit patterns.
#pragma omp parallel num_threads(threads)
  {
    const int t = omp_get_thread_num();
    uint32_t* offsets = bins->thread_counts.data() + static_cast<size_t>(t) * num_tiles;
    const int begin = static_cast<int>(static_cast<int64_t>(n) * t / threads);
    const int end = static_cast<int>(static_cast<int64_t>(n) * (t + 1) / threads);
    for (int i = begin; i < end; ++i) {
      const TileRect& r = rects[i];
      if (r.empty()) continue;
      uint32_t bits;
      std::memcpy(&bits, &depths[i], 4);
      const uint64_t key = (static_cast<uint64_t>(bits) << 32) | static_cast<uint32_t>(i);
      for (int ty = r.y0; ty < r.y1; ++ty) {
        for (int tx = r.x0; tx < r.x1; ++tx) bins->keys[offsets[ty * bins->tiles_x + tx]++] = key;
      }
    }
  }
  // Pass 3: sort each tile front to back.
  bins->ids.resize(total);
#pragma omp parallel for schedule(dynamic, 4)
  for (int tile = 0; tile < num_tiles; ++tile) {
    uint64_t* first = bins->keys.data() + bins->tile_start[tile];
    uint64_t* last = bins->keys.data() + bins->tile_start[tile + 1];
    std::sort(first, last);
    uint32_t* out = bins->ids.data() + bins->tile_start[tile];
    for (uint64_t* k = first; k != last; ++k) *out++ = static_cast<uint32_t>(*k);
  }
}

}  // namespace mgsr
