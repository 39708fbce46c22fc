// Helpers shared by the renderer tests.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/core/rng.h"
#include "mgsr/model/param_block.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr::testing {

// A small camera 3 units from the origin, looking at it (the random test scenes sit around it).
inline Camera RenderTestCamera(int w = 24, int h = 24) {
  return LookAtCamera({0.3, -3.0, 0.4}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), w, h, 30.0 * w / 24,
                      30.0 * h / 24);
}

inline double MaxAbsDiff(const Image& im, const std::vector<double>& ref) {
  double d = 0;
  for (size_t i = 0; i < im.size(); ++i) d = std::max(d, std::abs(im.data()[i] - ref[i]));
  return d;
}

// The bytes of images and float vectors, appended (renders compared to the bit, NaN included).
inline void AppendBytes(const Image& im, std::string* bytes) {
  bytes->append(reinterpret_cast<const char*>(im.data()), im.size() * sizeof(float));
}
inline void AppendBytes(const std::vector<float>& v, std::string* bytes) {
  bytes->append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(float));
}

// Binning by the projection's ellipses (`per_primitive` a primitive) leaves out tiles of the
// rectangles but changes no render or gradient: `render(bins)`, the forward and backward over
// those bins as bytes (AppendBytes), is the same for the whole rectangles' bins as for the
// fitted ones, which hold at most 90% of the entries.
template <class Projected, class RenderBytes>
void ExpectEllipseBinningRendersAsTheWholeRectangles(const Projected& p, int w, int h,
                                                     int per_primitive, const RenderBytes& render) {
  TileBins whole, fitted;
  BinPrimitives(p.rects, p.depth.data(), w, h, &whole);
  BinPrimitives(p.rects, p.depth.data(), w, h, &fitted, p.shapes.data(), per_primitive);
  EXPECT_LT(fitted.ids.size(), whole.ids.size() * 9 / 10) << whole.ids.size();
  EXPECT_TRUE(render(whole) == render(fitted));
}

// An image of uniform random values in [-1, 1) (an upstream gradient).
inline Image RandomImage(int w, int h, int channels, uint64_t seed) {
  Rng rng(seed);
  Image im(w, h, channels);
  for (size_t i = 0; i < im.size(); ++i) im.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  return im;
}

// A renderer's backward into gradient buffers that held NaN everywhere (the parameter blocks and
// the screen-mean statistic) gives what it gives into fresh ones (it writes every entry);
// `Gradients` is the renderer's gradient type (params: a model with Blocks(); ResizeAndZero).
// Returns the fresh gradients.
template <class Renderer, class Gradients, class Model, class Options, class Render, class Grad>
Gradients ExpectBackwardWritesEveryRow(Renderer* renderer, const Model& m, const Options& o,
                                       const Render& out, const Grad& grad,
                                       const std::string& what) {
  Gradients fresh, reused;
  renderer->Backward(m, o, out, grad, &fresh);
  reused.ResizeAndZero(m);
  for (const ParamBlock& b : reused.params.Blocks())
    std::fill(b.data->begin(), b.data->end(), std::nanf(""));
  std::fill(reused.mean2d.begin(), reused.mean2d.end(), std::nanf(""));
  renderer->Backward(m, o, out, grad, &reused);
  const std::vector<ParamBlock> a = fresh.params.Blocks(), b = reused.params.Blocks();
  for (size_t k = 0; k < a.size(); ++k) EXPECT_EQ(*a[k].data, *b[k].data) << a[k].name << what;
  EXPECT_EQ(fresh.mean2d, reused.mean2d) << "mean2d" << what;
  return fresh;
}

// The backward skips the tile entries the forward marked as blending no pixel
// (`Render::entry_blended`): marking every entry instead (nothing skipped) gives the same
// gradients to the bit. Expects the scene to leave more than a tenth of the entries unblended.
template <class Renderer, class Gradients, class Model, class Options, class Render, class Grad>
void ExpectSkippedEntriesChangeNoGradient(const Model& m, const Options& o, const Grad& grad) {
  Renderer renderer;
  Render out;
  renderer.Forward(m, o, &out);
  ASSERT_EQ(out.entry_blended.size(), renderer.bins().ids.size());
  const size_t skipped =
      static_cast<size_t>(std::count(out.entry_blended.begin(), out.entry_blended.end(), 0));
  EXPECT_GT(skipped, out.entry_blended.size() / 10)
      << skipped << " of " << out.entry_blended.size();
  EXPECT_LT(skipped, out.entry_blended.size());
  Gradients skipping, all;
  renderer.Backward(m, o, out, grad, &skipping);
  Render every = out;
  std::fill(every.entry_blended.begin(), every.entry_blended.end(), uint8_t{1});
  renderer.Backward(m, o, every, grad, &all);
  const std::vector<ParamBlock> a = skipping.params.Blocks(), b = all.params.Blocks();
  for (size_t k = 0; k < a.size(); ++k) EXPECT_EQ(*a[k].data, *b[k].data) << a[k].name;
}

}  // namespace mgsr::testing
