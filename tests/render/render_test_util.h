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

// An image of uniform random values in [-1, 1) (an upstream gradient).
inline Image RandomImage(int w, int h, int channels, uint64_t seed) {
  Rng rng(seed);
  Image im(w, h, channels);
  for (size_t i = 0; i < im.size(); ++i) im.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  return im;
}

// A renderer's backward into gradient buffers that held NaN everywhere gives what it gives into
// fresh ones (it writes every row the forward's primitives own); `Gradients` is the renderer's
// gradient type (params: a model with Blocks(); ResizeAndZero). Returns the fresh gradients.
template <class Renderer, class Gradients, class Model, class Options, class Render, class Grad>
Gradients ExpectBackwardWritesEveryRow(Renderer* renderer, const Model& m, const Options& o,
                                       const Render& out, const Grad& grad,
                                       const std::string& what) {
  Gradients fresh, reused;
  renderer->Backward(m, o, out, grad, &fresh);
  reused.ResizeAndZero(m);
  for (const ParamBlock& b : reused.params.Blocks())
    std::fill(b.data->begin(), b.data->end(), std::nanf(""));
  renderer->Backward(m, o, out, grad, &reused);
  const std::vector<ParamBlock> a = fresh.params.Blocks(), b = reused.params.Blocks();
  for (size_t k = 0; k < a.size(); ++k) EXPECT_EQ(*a[k].data, *b[k].data) << a[k].name << what;
  return fresh;
}

}  // namespace mgsr::testing
