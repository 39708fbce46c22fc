// Tile binning shared by both rasterizers (gsplat's "tile intersection" stage): every primitive
// covers a rectangle of 16x16-pixel tiles; each tile gets the list of primitives touching it,
// sorted front to back by depth. Built from one radix sort of the primitives by depth (ties by id)
// and a counting sort by tile over that order (both parallel, with a histogram per chunk), so
// every tile's list comes out in depth order: O(n), deterministic for any thread count.
#pragma once

#include <cstdint>
#include <limits>
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

// Where a primitive can blend, finer than its rectangle: the pixels whose centres
// (x + 0.5, y + 0.5) satisfy a dx^2 + 2 b dx dy + c dy^2 <= r, (dx, dy) = centre - (cx, cy), with
// a positive-definite form (an ellipse). Binning leaves out the tiles of a rectangle that the
// ellipse misses: a long thin splat lying diagonally reaches few of its box's tiles. Kept in the
// form binning reads row by row (TileEllipse::Of): the half-extents, the centre of each row and
// its half-width. The default (and a nearly degenerate form, or r infinite or NaN) is the whole
// rectangle.
struct TileEllipse {
  float cx = 0, cy = 0;
  float reach_x = std::numeric_limits<float>::infinity(), reach_y = reach_x;  // half-extents
  float slope = 0;       // row dy's centre is at dx = slope dy
  float k0 = 0, k1 = 0;  // row dy's half-width is sqrt(k0 - k1 dy^2)
  float left_row = 0;    // the row of the leftmost point; the rightmost one's is -left_row
  bool whole() const { return !(reach_x < std::numeric_limits<float>::infinity()); }

  // With margins against the float rounding of pixel loops that evaluate the same form: r is
  // widened by what the form's rounding can take off its value (more the nearer it is to
  // degenerate), and binning takes every tile's pixel centres kTileEllipseMarginPx further out.
  // (A caller whose pixel loops compute the shape another way widens r for them.) r < 0: no pixel.
  static TileEllipse Of(float cx, float cy, float a, float b, float c, float r);
};
constexpr float kTileEllipseMarginPx = 0.5f;
// Rectangles narrower than this many tiles are binned whole: a row of theirs has little to leave
// out, and working out its columns costs binning about what the passes gain (on a trained
// 1397 x 1030 capture both branches rendered faster with 4 here than with 3 or 8).
constexpr int kMinEllipseBinningWidth = 4;

// The tile columns [*first, *last) of tile row ty (of a width x height image) that ellipse `e`
// reaches (empty when *first >= *last).
void EllipseTileColumns(const TileEllipse& e, int ty, int width, int height, int* first, int* last);

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

// `rects[i]` for each primitive (empty = not drawn), `depths[i]` positive view depths. With
// `shapes` (`per_primitive` ellipses a primitive, at shapes[i * per_primitive]), a tile of a
// rectangle at least kMinEllipseBinningWidth tiles wide gets primitive i only if it lies within
// the hull of its ellipses' columns in that tile row (EllipseTileColumns).
void BinPrimitives(const std::vector<TileRect>& rects, const float* depths, int width, int height,
                   TileBins* bins, const TileEllipse* shapes = nullptr, int per_primitive = 0);

}  // namespace mgsr
