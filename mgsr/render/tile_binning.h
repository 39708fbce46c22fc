// Tile binning shared by both rasterizers (gsplat's "tile intersection" stage): every primitive
// covers a rectangle of 16x16-pixel tiles; each tile gets the list of primitives touching it,
// sorted front to back by depth. Built from one radix sort of the primitives by depth (ties by id)
// and a counting sort by tile over that order (both parallel, with a histogram per chunk), so
// every tile's list comes out in depth order: O(n), deterministic for any thread count.
#pragma once

#include <cstdint>
#include <vector>

namespace mgsr {

constexpr int kTileSize = 16;

// Tiles [x0, x1) x [y0, y1); empty when x1 <= x0 or y1 <= y0. In 16 bits (images up to
// kMaxTiles tiles, a million pixels, across): 8 bytes a primitive, so the binning's reads of them
// in depth order, at random, mostly stay in the core's cache (100k primitives: 0.8 MB, not 1.6).
struct TileRect {
  uint16_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  bool empty() const { return x1 <= x0 || y1 <= y0; }
};
constexpr int kMaxTiles = 65535;

// Tiles touched by a screen-space box centred at (cx, cy) with half-extents (rx, ry), in pixel
// coordinates where pixel (x, y) spans [x, x + 1) x [y, y + 1).
TileRect TileRectFromBox(float cx, float cy, float rx, float ry, int tiles_x, int tiles_y);

struct TileBins {
  int tiles_x = 0, tiles_y = 0;
  std::vector<uint32_t> tile_start;  // tiles_x * tiles_y + 1 offsets into ids
  std::vector<uint32_t> ids;         // primitive ids, per tile front to back

  // The tiles by decreasing entry count (ties by index): the order the rasterizers hand tiles to
  // threads, so the largest start first and the last ones to finish are small (an idle thread
  // waits at most for a small tile at the end of a pass).
  std::vector<int> tile_order;

  int num_tiles() const { return tiles_x * tiles_y; }
  // Scratch reused between calls (no allocation once warm).
  std::vector<uint32_t> chunk_counts;
  std::vector<uint32_t> order, order_keys, tmp_ids, tmp_keys;
  std::vector<TileRect> sorted_rects;  // the drawn primitives' rectangles in depth order
};

// `rects[i]` for each primitive (empty = not drawn), `depths[i]` positive view depths.
void BinPrimitives(const std::vector<TileRect>& rects, const float* depths, int width, int height,
                   TileBins* bins);

}  // namespace mgsr
