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

}  // namespace

void BinPrimitives(const std::vector<TileRect>& rects, const float* depths, int width, int height,
                   TileBins* bins) {
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
      const TileRect r = rects[bins->order[q]];
      bins->sorted_rects[q] = r;
      for (int ty = r.y0; ty < r.y1; ++ty) {
        for (int tx = r.x0; tx < r.x1; ++tx) ++counts[ty * bins->tiles_x + tx];
      }
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
