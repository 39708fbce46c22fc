// Stage tests of the render pipeline: SH evaluation and its backward, quaternion rotation and its
// backward, tile binning against brute force, the rasterizers' per-thread scratch.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>
#include <vector>

#include "mgsr/core/rng.h"
#include "mgsr/model/activations.h"
#include "mgsr/render/raster_scratch.h"
#include "mgsr/render/sh.h"
#include "mgsr/render/tile_binning.h"
#include "reference_gaussian_renderer.h"

namespace mgsr {
namespace {

TEST(ShTest, MatchesTheReferenceAndItsBackwardMatchesNumericDifferences) {
  Rng rng(4);
  for (int degree = 0; degree <= 3; ++degree) {
    float coeffs[48];
    for (float& c : coeffs) c = static_cast<float>(rng.Normal(0, 0.4));
    Eigen::Vector3d v(rng.Normal(), rng.Normal(), rng.Normal());
    const Eigen::Vector3f dir = v.normalized().cast<float>();
    float rgb[3];
    uint8_t clamped[3];
    EvalShColor(degree, coeffs, dir.data(), rgb, clamped);
    double ref[3];
    testing::ReferenceShColor(degree, coeffs, v.normalized(), ref);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(rgb[c], ref[c], 1e-6);
    // Backward through the normalisation, against central differences of the reference in v.
    const float d_rgb[3] = {0.3f, -0.7f, 0.5f};
    float d_coeffs[48] = {}, d_dir[3], d_v[3];
    EvalShColorBackward(degree, coeffs, dir.data(), clamped, d_rgb, d_coeffs, d_dir);
    const float vf[3] = {static_cast<float>(v.x()), static_cast<float>(v.y()),
                         static_cast<float>(v.z())};
    NormalizeBackward(vf, d_dir, d_v);
    auto loss = [&](const Eigen::Vector3d& vv, const float* cf) {
      double out[3];
      testing::ReferenceShColor(degree, cf, vv.normalized(), out);
      return d_rgb[0] * out[0] + d_rgb[1] * out[1] + d_rgb[2] * out[2];
    };
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d e = Eigen::Vector3d::Zero();
      e[k] = 1e-6;
      const double numeric = (loss(v + e, coeffs) - loss(v - e, coeffs)) / 2e-6;
      EXPECT_NEAR(d_v[k], numeric, 1e-4 * std::max(1.0, std::abs(numeric))) << "degree " << degree;
    }
    const int n = (degree + 1) * (degree + 1);
    for (int k = 0; k < 3 * n; ++k) {
      // Y_k(dir) from the reference, with a large DC term so nothing clamps.
      float base[48] = {}, one[48] = {};
      base[k % 3] = one[k % 3] = 5.0f;
      one[k] += 1.0f;
      double out_base[3], out_one[3];
      testing::ReferenceShColor(degree, base, v.normalized(), out_base);
      testing::ReferenceShColor(degree, one, v.normalized(), out_one);
      const double basis = out_one[k % 3] - out_base[k % 3];
      const double expected = clamped[k % 3] ? 0.0 : d_rgb[k % 3] * basis;
      EXPECT_NEAR(d_coeffs[k], expected, 1e-6);
    }
  }
}

// The writing backward the projections call (vectorised for 16 coefficients where the build has
// AVX-512) gives the adding form's bits on a zeroed row, for every coefficient count, with and
// without clamped channels, and adds d/d dir to what d_dir holds.
TEST(ShTest, WritingBackwardEqualsTheAddingFormToTheBit) {
  Rng rng(9);
  for (int trial = 0; trial < 200; ++trial) {
    const int degree = trial % 4, n = (degree + 1) * (degree + 1);
    float coeffs[48];
    for (float& c : coeffs) c = static_cast<float>(rng.Normal(0, 0.4));
    Eigen::Vector3d v(rng.Normal(), rng.Normal(), rng.Normal());
    const Eigen::Vector3f dir = v.normalized().cast<float>();
    float basis[kMaxShCoeffs], dbasis[kMaxShCoeffs][3];
    ShBasisWithGradient(degree, dir.data(), basis, dbasis);
    const uint8_t clamped[3] = {static_cast<uint8_t>(trial % 3 == 0), 0,
                                static_cast<uint8_t>(trial % 5 == 0)};
    const float d_rgb[3] = {static_cast<float>(rng.Normal()), static_cast<float>(rng.Normal()),
                            static_cast<float>(rng.Normal())};
    float added[48] = {}, written[48];
    std::fill(written, written + 48, std::nanf(""));
    float dir_added[3] = {0.25f, -1.5f, 3.0f}, dir_written[3] = {0.25f, -1.5f, 3.0f};
    EvalShColorBackwardFromBasis(n, basis, dbasis, coeffs, clamped, d_rgb, added, dir_added);
    WriteShColorBackwardFromBasis(n, basis, dbasis, coeffs, clamped, d_rgb, written, dir_written);
    for (int k = 0; k < 3 * n; ++k)
      ASSERT_EQ(std::memcmp(&added[k], &written[k], 4), 0) << "degree " << degree << " k " << k;
    for (int c = 0; c < 3; ++c)
      ASSERT_EQ(std::memcmp(&dir_added[c], &dir_written[c], 4), 0) << "degree " << degree;
    // And the colour from the basis is EvalShColor's.
    float rgb[3], rgb_basis[3];
    uint8_t cl[3], cl_basis[3];
    EvalShColor(degree, coeffs, dir.data(), rgb, cl);
    EvalShColorFromBasis(n, basis, coeffs, rgb_basis, cl_basis);
    for (int c = 0; c < 3; ++c) {
      ASSERT_EQ(std::memcmp(&rgb[c], &rgb_basis[c], 4), 0);
      ASSERT_EQ(cl[c], cl_basis[c]);
    }
  }
}

TEST(QuaternionTest, RotationBackwardMatchesNumericDifferences) {
  Rng rng(8);
  for (int trial = 0; trial < 5; ++trial) {
    float q[4];
    for (float& x : q) x = static_cast<float>(rng.Normal());
    float dR[9];
    for (float& x : dR) x = static_cast<float>(rng.Normal());
    float dq[4];
    QuaternionToRotationBackward(q, dR, dq);
    for (int k = 0; k < 4; ++k) {
      auto loss = [&](double delta) {
        Eigen::Quaterniond qq(q[0], q[1], q[2], q[3]);
        double* c = &qq.w();
        if (k > 0) c = &qq.coeffs()[k - 1];
        *c += delta;
        const Eigen::Matrix3d R = qq.normalized().toRotationMatrix();
        double l = 0;
        for (int i = 0; i < 9; ++i) l += dR[i] * R(i / 3, i % 3);
        return l;
      };
      const double numeric = (loss(1e-6) - loss(-1e-6)) / 2e-6;
      EXPECT_NEAR(dq[k], numeric, 1e-4 * std::max(1.0, std::abs(numeric)));
    }
  }
}

// The lists against a brute force: every tile's primitives sorted by (depth, id). With ties (half
// the depths on a coarse grid), primitives that touch no tile, and each thread count (the radix
// sort and the tile counts run in one chunk per thread).
class TileBinningTest : public ::testing::TestWithParam<int> {};

TEST_P(TileBinningTest, MatchesBruteForceSortsByDepthAndOrdersTilesBySize) {
  const int threads = GetParam();
  const int saved_threads = omp_get_max_threads();
  omp_set_num_threads(threads);
  Rng rng(2);
  const int W = 100, H = 70, n = 5000;
  std::vector<TileRect> rects(n);
  std::vector<float> depths(n);
  const int tx = (W + 15) / 16, ty = (H + 15) / 16;
  for (int i = 0; i < n; ++i) {
    rects[i] = TileRectFromBox(
        static_cast<float>(rng.Uniform(-20, 120)), static_cast<float>(rng.Uniform(-20, 90)),
        static_cast<float>(rng.Uniform(0, 30)), static_cast<float>(rng.Uniform(0, 30)), tx, ty);
    depths[i] = static_cast<float>(rng.Uniform(0.2, 10));
    if (i % 2 == 0) depths[i] = std::round(depths[i] * 4) / 4;  // ties
  }
  TileBins bins;
  BinPrimitives(rects, depths.data(), W, H, &bins);
  omp_set_num_threads(saved_threads);
  ASSERT_EQ(bins.tiles_x, tx);
  ASSERT_EQ(bins.tiles_y, ty);
  for (int tile = 0; tile < tx * ty; ++tile) {
    std::vector<std::pair<float, uint32_t>> expected;
    for (int i = 0; i < n; ++i) {
      const TileRect& r = rects[i];
      if (tile % tx >= r.x0 && tile % tx < r.x1 && tile / tx >= r.y0 && tile / tx < r.y1)
        expected.push_back({depths[i], i});
    }
    std::sort(expected.begin(), expected.end());
    ASSERT_EQ(bins.tile_start[tile + 1] - bins.tile_start[tile], expected.size()) << tile;
    for (size_t k = 0; k < expected.size(); ++k)
      ASSERT_EQ(bins.ids[bins.tile_start[tile] + k], expected[k].second);
  }
  // The tile order: every tile once, by decreasing entry count, ties by index.
  ASSERT_EQ(bins.tile_order.size(), static_cast<size_t>(tx * ty));
  std::vector<int> seen(tx * ty, 0);
  for (int i = 0; i < tx * ty; ++i) {
    const int tile = bins.tile_order[i];
    ASSERT_TRUE(tile >= 0 && tile < tx * ty);
    ++seen[tile];
    if (i == 0) continue;
    const int prev = bins.tile_order[i - 1];
    const uint32_t n = bins.tile_start[tile + 1] - bins.tile_start[tile],
                   n_prev = bins.tile_start[prev + 1] - bins.tile_start[prev];
    EXPECT_TRUE(n_prev > n || (n_prev == n && prev < tile)) << i;
  }
  for (int tile = 0; tile < tx * ty; ++tile) EXPECT_EQ(seen[tile], 1) << tile;
  // A box entirely off screen touches no tile.
  EXPECT_TRUE(TileRectFromBox(-50, -50, 10, 10, tx, ty).empty());
  EXPECT_TRUE(TileRectFromBox(200, 20, 10, 10, tx, ty).empty());
}

INSTANTIATE_TEST_SUITE_P(Threads, TileBinningTest, ::testing::Values(1, 2, 3));

// An ellipse's tile columns per tile row hold every tile with a pixel centre inside it (the form
// in double at most r), and leave out tiles of its box: long thin ellipses at random angles,
// nearly degenerate ones, off-centre ones, on a 200 x 120 image. Binning with such shapes gives the
// whole rectangles' lists less exactly the tiles their columns leave out, in the same order.
TEST(TileBinningTest, EllipseColumnsHoldEveryReachedTileAndBinningKeepsOnlyThose) {
  Rng rng(5);
  const int W = 200, H = 120, tiles_x = (W + 15) / 16, tiles_y = (H + 15) / 16;
  const int n = 400;
  std::vector<TileRect> rects(n);
  std::vector<TileEllipse> shapes(n);
  std::vector<float> depths(n);
  size_t box_tiles = 0, reached_tiles = 0;
  for (int i = 0; i < n; ++i) {
    // A form with axes s1 >= s2 at angle t: a dx^2 + 2 b dx dy + c dy^2 <= r.
    const double t = rng.Uniform(0, M_PI), s1 = rng.Uniform(2, 60);
    const double s2 = i % 10 == 0 ? s1 * 1e-3 : rng.Uniform(0.3, s1);
    const double ct = std::cos(t), st = std::sin(t);
    const float a = static_cast<float>(ct * ct / (s1 * s1) + st * st / (s2 * s2));
    const float b = static_cast<float>(ct * st * (1 / (s1 * s1) - 1 / (s2 * s2)));
    const float c = static_cast<float>(st * st / (s1 * s1) + ct * ct / (s2 * s2));
    const float r = static_cast<float>(rng.Uniform(0.5, 9)), cx = rng.Uniform(-30, 230),
                cy = rng.Uniform(-30, 150);
    shapes[i] = TileEllipse::Of(cx, cy, a, b, c, r);
    // Its box (half-widths sqrt(r c / det), sqrt(r a / det)).
    const double det = double(a) * c - double(b) * b;
    rects[i] = TileRectFromBox(cx, cy, static_cast<float>(std::sqrt(r * c / det)) + 1,
                               static_cast<float>(std::sqrt(r * a / det)) + 1, tiles_x, tiles_y);
    depths[i] = static_cast<float>(rng.Uniform(0.2, 10));
    for (int ty = rects[i].y0; ty < rects[i].y1; ++ty) {
      int first, last;
      EllipseTileColumns(shapes[i], ty, W, H, &first, &last);
      for (int tx = rects[i].x0; tx < rects[i].x1; ++tx) {
        ++box_tiles;
        bool reached = false;
        for (int y = ty * 16; y < std::min(H, ty * 16 + 16) && !reached; ++y) {
          for (int x = tx * 16; x < std::min(W, tx * 16 + 16) && !reached; ++x) {
            const double dx = x + 0.5 - cx, dy = y + 0.5 - cy;
            reached = a * dx * dx + 2.0 * b * dx * dy + c * dy * dy <= r;
          }
        }
        reached_tiles += reached;
        if (reached) {
          ASSERT_TRUE(tx >= first && tx < last) << i << " " << tx << " " << ty;
        }
      }
    }
  }
  // The columns do leave tiles out (the boxes' tiles that hold no reached centre).
  int kept = 0;
  for (int i = 0; i < n; ++i) {
    for (int ty = rects[i].y0; ty < rects[i].y1; ++ty) {
      int first, last;
      EllipseTileColumns(shapes[i], ty, W, H, &first, &last);
      kept += std::max(0, std::min<int>(last, rects[i].x1) - std::max<int>(first, rects[i].x0));
    }
  }
  EXPECT_LT(kept, 0.8 * box_tiles) << reached_tiles << " reached of " << box_tiles;
  // Degenerate and infinite forms keep the whole row; a negative r none.
  int first, last;
  EllipseTileColumns(TileEllipse::Of(50, 50, 1, 1, 1, 4), 3, W, H, &first, &last);
  EXPECT_EQ(first, 0);
  EXPECT_EQ(last, tiles_x);
  EllipseTileColumns(TileEllipse(), 3, W, H, &first, &last);
  EXPECT_EQ(last - first, tiles_x);
  EllipseTileColumns(TileEllipse::Of(std::nanf(""), 50, 1, 0, 1, 4), 3, W, H, &first, &last);
  EXPECT_EQ(last - first, tiles_x);
  EllipseTileColumns(TileEllipse::Of(50, 50, 1e-38f, 0, 1, 4), 3, W, H, &first, &last);
  EXPECT_EQ(last - first, tiles_x);
  EllipseTileColumns(TileEllipse::Of(50, 50, 1, 0, 1, -1), 3, W, H, &first, &last);
  EXPECT_GE(first, last);
  // Binning: the whole rectangles' lists, less the columns each row leaves out.
  TileBins whole, fitted;
  BinPrimitives(rects, depths.data(), W, H, &whole);
  BinPrimitives(rects, depths.data(), W, H, &fitted, shapes.data(), 1);
  for (int tile = 0; tile < tiles_x * tiles_y; ++tile) {
    std::vector<uint32_t> expected;
    for (uint32_t e = whole.tile_start[tile]; e < whole.tile_start[tile + 1]; ++e) {
      const uint32_t id = whole.ids[e];
      const TileRect& r = rects[id];
      EllipseTileColumns(shapes[id], tile / tiles_x, W, H, &first, &last);
      // (Narrow rectangles are binned whole.)
      const bool narrow = r.x1 - r.x0 < kMinEllipseBinningWidth;
      if (narrow || (tile % tiles_x >= first && tile % tiles_x < last)) expected.push_back(id);
    }
    const std::vector<uint32_t> got(fitted.ids.begin() + fitted.tile_start[tile],
                                    fitted.ids.begin() + fitted.tile_start[tile + 1]);
    ASSERT_EQ(got, expected) << tile;
  }
  EXPECT_LT(fitted.ids.size(), whole.ids.size());
}

// Which thread draws which tile depends on scheduling, so every thread's buffers must be sized
// before the parallel loops: for the largest tile's primitives and for the most pixel arrays a
// pass (forward or backward) carves out. A thread that first drew a backward tile late grew its
// pixel state then, and a steady training iteration allocated (#20).
TEST(RasterScratchTest, EnsureScratchSizesEveryThreadForAnyTileAndPass) {
  TileBins bins;
  bins.tiles_x = 3;
  bins.tiles_y = 1;
  bins.tile_start = {0, 2, 2, 7};  // the largest tile holds 5 entries, one is empty
  bins.ids = {0, 1, 0, 1, 2, 3, 4};
  const int fields = 20, threads = 3;
  RasterScratch scratch;
  raster_internal::EnsureScratch(&scratch, threads, bins, fields);
  ASSERT_EQ(scratch.tile_data.size(), static_cast<size_t>(threads));
  ASSERT_EQ(scratch.pixel_state.size(), static_cast<size_t>(threads));
  for (int t = 0; t < threads; ++t) {
    EXPECT_GE(scratch.tile_data[t].capacity(), 5u * fields) << t;
    std::vector<float>* state = &scratch.pixel_state[t];
    const float* before = state->data();
    ASSERT_NE(before, nullptr) << t;
    const raster_internal::PixelArrays st(state, raster_internal::kMaxPixelArrays);
    EXPECT_EQ(state->data(), before) << "thread " << t << "'s pixel state grew in the loop";
    EXPECT_EQ(st[raster_internal::kMaxPixelArrays - 1] + raster_internal::kTilePixels,
              state->data() + state->size());
  }
}

// The rows (and columns) a primitive's loops visit are exactly those whose centres the pixel
// test accepts: the loops no longer test each row's |y + 0.5 - m| <= r themselves. Boundaries
// where m - r - 0.5 is an integer, empty ranges, and values so large that the estimate rounds by
// more than one index, against brute force; and the 8-column window holds every reached column.
// The 3DGS backward drops a chain's pixels whose exponent is below FaintPowerBound: there its
// alpha o exp(power), as the rasterizer computes it, must be below 1/255, for every opacity; and
// the bound should not be loose by much more than its 0.086 (log2) slack.
TEST(RasterScratchTest, FaintPowerBoundLeavesOutOnlyPixelsThatDoNotBlend) {
  const float min_alpha = 1.0f / 255.0f, log_min_alpha = -5.5413f;
  int checked = 0;
  for (int i = 0; i <= 2000000; ++i) {
    const float o = min_alpha + (1.0f - min_alpha) * static_cast<float>(i) / 2000000.0f;
    const float bound = raster_internal::FaintPowerBound(o, log_min_alpha);
    const float alpha = o * simd::Exp(simd::Splat<simd::F16>(bound))[0];
    ASSERT_LT(alpha, min_alpha) << "opacity " << o;
    ASSERT_GT(bound, std::log(static_cast<double>(min_alpha) / o) - 0.065) << "opacity " << o;
    ++checked;
  }
  // Powers of two and their neighbours (the bits' approximation is exact at powers of two).
  for (float o = 1.0f; o >= min_alpha; o *= 0.5f) {
    for (const float v : {o, std::nextafter(o, 0.0f), std::nextafter(o, 2.0f)}) {
      if (v < min_alpha || v > 1.0f) continue;
      const float bound = raster_internal::FaintPowerBound(v, log_min_alpha);
      ASSERT_LT(v * simd::Exp(simd::Splat<simd::F16>(bound))[0], min_alpha) << "opacity " << v;
    }
  }
  EXPECT_GT(checked, 2000000);
}

TEST(RasterScratchTest, ReachedRangeIsExactlyTheCentresThePixelTestAccepts) {
  Rng rng(9);
  const int first = 16, last = 31;
  std::vector<std::pair<float, float>> cases = {
      {20.5f, 0.0f},        {20.5f, 3.0f},         {19.0f, 2.5f},
      {5.0f, 3.0f},         {40.0f, 2.0f},         {24.0f, 1e9f},
      {3e8f, 3e8f - 20.0f}, {-3e8f, 3e8f + 25.0f}, {1e8f, 1e8f - 24.5f}};
  for (int i = 0; i < 20000; ++i) {
    const float m = static_cast<float>(rng.Uniform(0, 48));
    const float r = i % 3 == 0 ? std::floor(m) + 0.5f - m + static_cast<float>(rng.Uniform(0, 6))
                               : static_cast<float>(rng.Uniform(0, 12));
    cases.push_back({m, std::max(r, 0.0f)});
  }
  for (const auto& [m, r] : cases) {
    int lo = 0, hi = 0;
    raster_internal::ReachedRange(m, r, first, last, &lo, &hi);
    for (int y = first; y <= last; ++y) {
      const bool accepted = std::abs((static_cast<float>(y) + 0.5f) - m) <= r;
      ASSERT_EQ(accepted, lo <= y && y <= hi) << "m " << m << " r " << r << " row " << y;
    }
    const raster_internal::ColumnWindow w = raster_internal::WindowFor(m, r, first);
    if (w.half) {
      for (int x = 0; x < kTileSize; ++x) {
        if (raster_internal::CentreReached(m, r, first + x)) {
          EXPECT_TRUE(w.first <= x && x < w.first + 8) << "m " << m << " r " << r << " col " << x;
        }
      }
    }
  }
}

// The gradient reduction against a plain serial sum in tile and entry order: the same bits, with
// rows of 15 and 18 floats (the two rasterizers': overlapping 8-float vectors) and of 5 (scalar),
// tiles that use only a prefix of their entries, tiles longer than the scan's 256-entry chunks,
// and one, two and three ranges.
template <int stride>
void ExpectReductionMatchesSerialSums() {
  Rng rng(11);
  TileBins bins;
  bins.tiles_x = 4;
  bins.tiles_y = 1;
  const size_t num = 97;
  bins.tile_start = {0};
  std::vector<uint32_t> used;
  for (int tile = 0; tile < 4; ++tile) {
    const uint32_t n = tile == 2 ? 700 : 40 + 13 * tile;
    for (uint32_t j = 0; j < n; ++j) bins.ids.push_back(static_cast<uint32_t>(rng.Uniform(0, num)));
    bins.tile_start.push_back(static_cast<uint32_t>(bins.ids.size()));
    used.push_back(tile == 1 ? n / 2 : n);
  }
  std::vector<float> entry(bins.ids.size() * stride);
  for (float& v : entry) v = static_cast<float>(rng.Normal());
  std::vector<float> expected(num * stride, 0.0f);
  for (int tile = 0; tile < 4; ++tile) {
    for (uint32_t j = 0; j < used[tile]; ++j) {
      const uint32_t e = bins.tile_start[tile] + j;
      for (int q = 0; q < stride; ++q) expected[bins.ids[e] * stride + q] += entry[e * stride + q];
    }
  }
  const int saved = omp_get_max_threads();
  for (int threads : {1, 2, 3}) {
    omp_set_num_threads(threads);
    std::vector<float> sums(5, 1.0f);  // stale contents are overwritten
    ReduceEntryGradients<stride>(bins, used, entry, num, &sums);
    ASSERT_EQ(sums.size(), expected.size());
    for (size_t k = 0; k < sums.size(); ++k)
      ASSERT_EQ(sums[k], expected[k])
          << "stride " << stride << ", " << threads << " threads, " << k;
  }
  omp_set_num_threads(saved);
}

TEST(RasterScratchTest, ReduceEntryGradientsEqualsTheSerialSumsInEntryOrder) {
  ExpectReductionMatchesSerialSums<15>();
  ExpectReductionMatchesSerialSums<18>();
  ExpectReductionMatchesSerialSums<5>();
}

}  // namespace
}  // namespace mgsr
