// The learnt background: an equirectangular map looked up bilinearly per pixel direction. Its
// render against the definition, its gradient against central differences in double precision,
// and the trainer-side background (Adam steps, checkpoint round trip).
#include "mgsr/model/environment_map.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "mgsr/core/rng.h"
#include "solvers/environment_background.h"
#include "test_util.h"

namespace mgsr {
namespace {

Camera SkyCamera() {
  // Looking up at the horizon: most pixels see the upper half, some the lower.
  return LookAtCamera({0, 0, 0}, {1, 0.3, 0.4}, Eigen::Vector3d::UnitZ(), 24, 18, 14, 14);
}

TEST(EnvironmentMapTest, TapsWrapInLongitudeClampAtThePolesAndInterpolate) {
  EnvironmentMap map;
  map.Reset(8, 4, 0.0f);
  // A direction at a texel centre reads that texel alone: texel (i, j) is at longitude
  // (i + 0.5) / 8 * 2 pi - pi, polar angle (j + 0.5) / 4 * pi.
  const double lon = (3 + 0.5) / 8 * 2 * M_PI - M_PI, polar = (1 + 0.5) / 4 * M_PI;
  const Eigen::Vector3d d(std::sin(polar) * std::cos(lon), std::sin(polar) * std::sin(lon),
                          std::cos(polar));
  const EnvironmentTaps t = map.Taps(d);
  double at_texel = 0, total = 0;
  for (int k = 0; k < 4; ++k) {
    total += t.weight[k];
    if (t.texel[k] == 1 * 8 + 3) at_texel += t.weight[k];
  }
  EXPECT_NEAR(total, 1.0, 1e-12);
  EXPECT_NEAR(at_texel, 1.0, 1e-9);
  // Just past longitude pi the taps wrap to column 0; straight up reads the top row only.
  const EnvironmentTaps wrap = map.Taps(Eigen::Vector3d(-1, -1e-3, 0).normalized());
  bool col0 = false, col7 = false;
  for (int k = 0; k < 4; ++k) {
    col0 |= wrap.weight[k] > 0 && wrap.texel[k] % 8 == 0;
    col7 |= wrap.weight[k] > 0 && wrap.texel[k] % 8 == 7;
  }
  EXPECT_TRUE(col0 && col7);
  const EnvironmentTaps up = map.Taps(Eigen::Vector3d::UnitZ());
  for (int k = 0; k < 4; ++k) EXPECT_LT(up.texel[k], 8);
}

// The colour the renderer's taps of pixel i give, from `values` (any scalar type).
template <typename T>
void LookupThroughRendererTaps(const EnvironmentMap& map, const EnvironmentRenderer::PixelTaps& t,
                               const std::vector<T>& values, T rgb[3]) {
  int texel[4];
  float weight[4];
  t.Expand(map.width, texel, weight);
  for (int c = 0; c < 3; ++c) {
    rgb[c] = 0;
    for (int k = 0; k < 4; ++k) rgb[c] += weight[k] * values[3 * texel[k] + c];
  }
}

TEST(EnvironmentMapTest, RendererTapsAgreeWithTheDefinition) {
  // The renderer computes its taps in float with a polynomial arctangent: each texel's weight
  // within 2e-4 of the double definition's, for a view of the sky and one across the map's
  // longitude seam (looking along -x).
  EnvironmentMap map;
  map.Reset(64, 32, 0.0f);
  const Camera cameras[2] = {SkyCamera(), LookAtCamera({0, 0, 0}, {-1, 0.05, -0.2},
                                                       Eigen::Vector3d::UnitZ(), 40, 30, 20, 20)};
  for (const Camera& cam : cameras) {
    EnvironmentRenderer renderer;
    const std::vector<EnvironmentRenderer::PixelTaps>& taps = renderer.TapsFor(map, cam);
    ASSERT_EQ(taps.size(), static_cast<size_t>(cam.width) * cam.height);
    double worst = 0;
    std::set<int> columns;
    for (int y = 0; y < cam.height; ++y) {
      for (int x = 0; x < cam.width; ++x) {
        const Eigen::Vector3d d =
            (cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5)).normalized();
        const EnvironmentTaps expected = map.Taps(d);
        const EnvironmentRenderer::PixelTaps& t = taps[static_cast<size_t>(y) * cam.width + x];
        // Both as one weight per texel.
        std::map<int, double> a, b;
        for (int k = 0; k < 4; ++k) a[expected.texel[k]] += expected.weight[k];
        int texel[4];
        float weight[4];
        t.Expand(64, texel, weight);
        for (int k = 0; k < 4; ++k) b[texel[k]] += weight[k];
        for (const auto& [texel_index, w] : a)
          worst = std::max(worst, std::abs(w - b[texel_index]));
        for (const auto& [texel_index, w] : b)
          worst = std::max(worst, std::abs(w - a[texel_index]));
        columns.insert(t.x0);
      }
    }
    EXPECT_LT(worst, 2e-4);
    if (&cam == &cameras[1]) {
      EXPECT_TRUE(columns.count(0) && columns.count(63));  // the seam
    }
  }
}

TEST(EnvironmentMapTest, GradientMatchesNumericDifferentiationInDoublePrecision) {
  EnvironmentMap map;
  map.Reset(16, 8, 0.0f);
  Rng rng(3);
  for (float& v : map.texels) v = static_cast<float>(rng.Uniform(0, 1));
  const Camera cam = SkyCamera();
  Image upstream(cam.width, cam.height, 3);
  for (size_t i = 0; i < upstream.size(); ++i)
    upstream.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  EnvironmentRenderer renderer;
  Image rendered;
  renderer.Render(map, cam, &rendered);
  std::vector<float> analytic;
  renderer.Backward(map, cam, upstream, &analytic);
  ASSERT_EQ(analytic.size(), map.texels.size());
  // The loss sum(upstream * render) in double: each pixel's taps, the texels' weighted sum.
  const std::vector<EnvironmentRenderer::PixelTaps> taps = renderer.TapsFor(map, cam);
  std::vector<double> values(map.texels.begin(), map.texels.end());
  auto loss = [&](const std::vector<double>& v) {
    double l = 0;
    for (int y = 0; y < cam.height; ++y) {
      for (int x = 0; x < cam.width; ++x) {
        double rgb[3];
        LookupThroughRendererTaps(map, taps[static_cast<size_t>(y) * cam.width + x], v, rgb);
        for (int c = 0; c < 3; ++c) l += upstream.at(c, y, x) * rgb[c];
      }
    }
    return l;
  };
  // The render is the same lookup in float.
  {
    double rgb[3];
    LookupThroughRendererTaps(map, taps[7 * cam.width + 5], values, rgb);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(rendered.at(c, 7, 5), rgb[c], 1e-6);
  }
  int seen = 0;
  for (size_t k = 0; k < values.size(); ++k) {
    const double numeric = testing::CentralDifference([&] { return loss(values); }, &values[k]);
    EXPECT_NEAR(analytic[k], numeric, 1e-4 * std::abs(numeric) + 1e-6) << "texel value " << k;
    seen += std::abs(numeric) > 1e-3;
  }
  EXPECT_GT(seen, 10);
  EXPECT_LT(seen, static_cast<int>(values.size()));  // the camera sees part of the sphere
}

TEST(EnvironmentMapTest, GradientIsTheSameOnOneAndTwoThreads) {
  // The row bands' sums are added in band order, whatever the number of threads.
  EnvironmentMap map;
  map.Reset(64, 32, 0.0f);
  Rng rng(5);
  for (float& v : map.texels) v = static_cast<float>(rng.Uniform(0, 1));
  const Camera cam =
      LookAtCamera({0, 0, 0}, {1, 0.3, 0.4}, Eigen::Vector3d::UnitZ(), 301, 203, 150, 150);
  Image upstream(cam.width, cam.height, 3);
  for (size_t i = 0; i < upstream.size(); ++i)
    upstream.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  std::vector<float> grads[2];
  Image renders[2];
  const int saved = omp_get_max_threads();
  for (int threads = 1; threads <= 2; ++threads) {
    omp_set_num_threads(threads);
    EnvironmentRenderer renderer;
    renderer.Render(map, cam, &renders[threads - 1]);
    renderer.Backward(map, cam, upstream, &grads[threads - 1]);
  }
  omp_set_num_threads(saved);
  EXPECT_EQ(grads[0], grads[1]);
  EXPECT_TRUE(
      std::equal(renders[0].data(), renders[0].data() + renders[0].size(), renders[1].data()));
}

TEST(EnvironmentBackgroundTest, LearnsASkyAndResumesExactly) {
  EnvironmentOptions o;
  o.width = 16;
  o.height = 8;
  EnvironmentBackground env(o), copy(o);
  const Camera cam = SkyCamera();
  // Fit the background to a sky of (0.3, 0.5, 0.9) by the gradient of 0.5 |render - sky|^2.
  auto step = [&](EnvironmentBackground* e) {
    Image bg;
    e->Render(cam, &bg);
    Image grad(cam.width, cam.height, 3);
    const float sky[3] = {0.3f, 0.5f, 0.9f};
    for (int c = 0; c < 3; ++c) {
      for (size_t i = 0; i < grad.plane_size(); ++i) grad.plane(c)[i] = bg.plane(c)[i] - sky[c];
    }
    return e->Step(cam, grad);
  };
  for (int i = 0; i < 300; ++i) ASSERT_EQ(step(&env), "");
  Image bg;
  env.Render(cam, &bg);
  EXPECT_NEAR(bg.at(0, 9, 12), 0.3f, 0.02f);
  EXPECT_NEAR(bg.at(2, 9, 12), 0.9f, 0.02f);
  // Checkpoint round trip: the copy continues exactly.
  BinaryWriter w;
  env.Save(&w);
  const std::string data = w.data();
  BinaryReader r("env.ckpt", data);
  ASSERT_TRUE(copy.Read(&r).ok());
  copy.CommitRead();
  for (int i = 0; i < 5; ++i) {
    step(&env);
    step(&copy);
  }
  EXPECT_EQ(env.map().texels, copy.map().texels);
  // A map of another size is refused naming the file.
  EnvironmentOptions other = o;
  other.width = 32;
  EnvironmentBackground wrong(other);
  BinaryReader r2("env.ckpt", data);
  const Status s = wrong.Read(&r2);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("env.ckpt"), std::string::npos);
  // A gradient with a NaN is reported and leaves the map finite.
  Image nan_grad(cam.width, cam.height, 3);
  nan_grad.data()[5] = std::nanf("");
  const std::vector<float> before = env.map().texels;
  EXPECT_EQ(env.Step(cam, nan_grad), "environment");
  EXPECT_EQ(env.map().texels, before);
}

}  // namespace
}  // namespace mgsr
