#include "mgsr/render/gaussian_renderer.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <functional>

#include "mgsr/core/rng.h"
#include "mgsr/render/raster_scratch.h"
#include "reference_gaussian_renderer.h"
#include "render_test_util.h"
#include "test_util.h"

namespace mgsr {
namespace {

GaussianModel RandomScene(int n, uint64_t seed, double scale_lo = 0.05, double scale_hi = 0.25) {
  Rng rng(seed);
  GaussianModel m;
  m.max_sh_degree = 3;
  m.Resize(n);
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) m.means[3 * i + k] = static_cast<float>(rng.Uniform(-0.6, 0.6));
    for (int k = 0; k < 3; ++k)
      m.log_scales[3 * i + k] = static_cast<float>(std::log(rng.Uniform(scale_lo, scale_hi)));
    for (int k = 0; k < 4; ++k) m.quats[4 * i + k] = static_cast<float>(rng.Normal());
    m.opacity_logits[i] = static_cast<float>(rng.Uniform(-2.0, 1.5));
    m.ref_opacity_logits[i] = static_cast<float>(rng.Uniform(-2.0, 1.0));
    m.beta_logits[i] = static_cast<float>(rng.Uniform(-2.0, 2.0));
  }
  for (float& v : m.sh) v = static_cast<float>(rng.Normal(0, 0.25));
  for (float& v : m.ref_sh) v = static_cast<float>(rng.Normal(0, 0.25));
  return m;
}

GaussianRenderOptions Options(const Camera& cam, bool reflection = true) {
  GaussianRenderOptions o;
  o.camera = cam;
  o.sh_degree = 3;
  o.reflection = reflection;
  o.background[0] = 0.2f;
  o.background[1] = 0.5f;
  o.background[2] = 0.7f;
  return o;
}

class GaussianRendererTest : public ::testing::TestWithParam<bool> {};

TEST_P(GaussianRendererTest, TiledRenderMatchesTheReference) {
  const bool reflection = GetParam();
  for (uint64_t seed : {1, 2, 3, 4}) {
    // 40 x 36 pixels: several tiles, partial tiles at the border.
    const Camera cam = testing::RenderTestCamera(40, 36);
    const GaussianModel m = RandomScene(30, seed);
    GaussianRenderer renderer;
    GaussianRender out;
    const GaussianRenderOptions o = Options(cam, reflection);
    renderer.Forward(m, o, &out);
    const double bg[3] = {0.2, 0.5, 0.7};
    const auto ref = testing::RenderGaussiansReference(m, cam, 3, reflection, bg);
    EXPECT_LT(testing::MaxAbsDiff(out.color, ref.color), 1e-5) << seed;
    EXPECT_LT(testing::MaxAbsDiff(out.tran, ref.tran), 1e-5) << seed;
    EXPECT_LT(testing::MaxAbsDiff(out.alpha, ref.alpha), 1e-5) << seed;
    EXPECT_LT(testing::MaxAbsDiff(out.depth, ref.depth), 1e-5 * 4)
        << seed;  // depths are ~3: relative 1e-5
    if (reflection) {
      EXPECT_LT(testing::MaxAbsDiff(out.ref, ref.ref), 1e-5) << seed;
      EXPECT_LT(testing::MaxAbsDiff(out.weight, ref.weight), 1e-5) << seed;
    }
    // The scene is not trivial: most pixels are covered.
    double covered = 0;
    for (size_t i = 0; i < out.alpha.size(); ++i) covered += out.alpha.data()[i] > 0.1f;
    EXPECT_GT(covered, 0.3 * out.alpha.size());
  }
}

// Recording contributions leaves the image bitwise unchanged, and the per-Gaussian sums add up to
// the image's summed blend weights: 1 - T per pixel (plus 1 - Tr with reflection); a Gaussian
// behind the camera contributes nothing.
TEST_P(GaussianRendererTest, ContributionsSumToTheBlendedWeights) {
  const bool reflection = GetParam();
  const Camera cam = testing::RenderTestCamera(40, 36);
  GaussianModel m = RandomScene(30, 5);
  m.means[0] = 0.6f;
  m.means[1] = -6.0f;  // behind the camera (at y = -3, looking along +y)
  GaussianRenderer renderer;
  GaussianRender plain, recorded;
  GaussianRenderOptions o = Options(cam, reflection);
  renderer.Forward(m, o, &plain);
  EXPECT_TRUE(plain.contribution.empty());
  o.record_contribution = true;
  renderer.Forward(m, o, &recorded);
  EXPECT_TRUE(std::equal(plain.color.data(), plain.color.data() + plain.color.size(),
                         recorded.color.data()));
  ASSERT_EQ(recorded.contribution.size(), m.size());
  double sum = 0, expected = 0;
  for (float c : recorded.contribution) sum += c;
  for (size_t p = 0; p < recorded.final_t.size(); ++p)
    expected += (1.0 - recorded.final_t[p]) + (reflection ? 1.0 - recorded.final_tr[p] : 0.0);
  EXPECT_NEAR(sum, expected, 1e-4 * expected);
  EXPECT_GT(expected, 100.0);
  EXPECT_EQ(recorded.contribution[0], 0.0f);
}

INSTANTIATE_TEST_SUITE_P(WithAndWithoutReflection, GaussianRendererTest, ::testing::Bool());

// Every raw parameter's gradient, for an upstream gradient on each output buffer in turn, against
// central differences of the double-precision reference.
TEST(GaussianRendererGradientTest, AllParametersAllOutputsMatchNumericDifferentiation) {
  const Camera cam = testing::RenderTestCamera();
  const GaussianModel m = RandomScene(8, 11, 0.1, 0.3);
  const GaussianRenderOptions o = Options(cam);
  const double bg[3] = {0.2, 0.5, 0.7};
  GaussianRenderer renderer;
  GaussianRender out;
  renderer.Forward(m, o, &out);
  const size_t np = static_cast<size_t>(cam.width) * cam.height;

  const char* outputs[] = {"color", "tran", "ref", "weight", "depth", "alpha"};
  for (int which = 0; which < 6; ++which) {
    Rng rng(100 + which);
    GaussianRenderGrad grad;
    Image* target[] = {&grad.color, &grad.tran, &grad.ref, &grad.weight, &grad.depth, &grad.alpha};
    const int channels = which < 3 ? 3 : 1;
    *target[which] = Image(cam.width, cam.height, channels);
    for (size_t i = 0; i < target[which]->size(); ++i)
      target[which]->data()[i] = static_cast<float>(rng.Uniform(-1, 1));
    const Image& upstream = *target[which];
    GaussianGradients analytic;
    renderer.Backward(m, o, out, grad, &analytic);

    auto loss = [&](const testing::GaussianModelD& md) {
      const auto r = testing::RenderGaussiansReference(md, cam, 3, true, bg);
      const std::vector<double>* buf[] = {&r.color, &r.tran, &r.ref, &r.weight, &r.depth, &r.alpha};
      double l = 0;
      for (size_t i = 0; i < channels * np; ++i) l += upstream.data()[i] * (*buf[which])[i];
      return l;
    };
    testing::GaussianModelD base(m);
    struct Block {
      const char* name;
      std::vector<double> testing::GaussianModelD::*field;
      const std::vector<float>* analytic;
    };
    const Block blocks[] = {
        {"means", &testing::GaussianModelD::means, &analytic.params.means},
        {"log_scales", &testing::GaussianModelD::log_scales, &analytic.params.log_scales},
        {"quats", &testing::GaussianModelD::quats, &analytic.params.quats},
        {"opacity", &testing::GaussianModelD::opacity_logits, &analytic.params.opacity_logits},
        {"sh", &testing::GaussianModelD::sh, &analytic.params.sh},
        {"ref_sh", &testing::GaussianModelD::ref_sh, &analytic.params.ref_sh},
        {"ref_opacity", &testing::GaussianModelD::ref_opacity_logits,
         &analytic.params.ref_opacity_logits},
        {"beta", &testing::GaussianModelD::beta_logits, &analytic.params.beta_logits},
    };
    for (const Block& b : blocks) {
      std::vector<double>& values = base.*(b.field);
      std::vector<double> numeric(values.size());
      double max_abs = 0;
      for (size_t k = 0; k < values.size(); ++k) {
        const double h = 1e-6, keep = values[k];
        values[k] = keep + h;
        const double lp = loss(base);
        values[k] = keep - h;
        const double lm = loss(base);
        values[k] = keep;
        numeric[k] = (lp - lm) / (2 * h);
        max_abs = std::max(max_abs, std::abs(numeric[k]));
      }
      int checked = 0;
      for (size_t k = 0; k < values.size(); ++k) {
        const double a = (*b.analytic)[k], n = numeric[k];
        // Relative 1e-3 where the derivative is not tiny (> 1e-4 of the block's largest).
        const double tol = 1e-3 * std::abs(n) + 1e-4 * max_abs + 1e-7;
        EXPECT_NEAR(a, n, tol) << outputs[which] << " d/d " << b.name << "[" << k << "]";
        checked += std::abs(n) > 1e-4 * max_abs;
      }
      if (max_abs > 0) {
        EXPECT_GT(checked, static_cast<int>(values.size()) / 4) << outputs[which] << " " << b.name;
      }
      if (which == 0)
        std::printf("[ grad     ] color d/d %-11s %3d of %3zu derivatives checked (not tiny)\n",
                    b.name, checked, values.size());
    }
  }
}

// A background per pixel (a learnt environment): the render matches the reference, the Gaussians'
// gradients still match numeric differentiation, and d loss / d background is T_N times the
// colour and transmitted gradients (GaussianBackgroundGradient), checked numerically too.
TEST(GaussianRendererGradientTest, PerPixelBackgroundMatchesNumericDifferentiation) {
  const Camera cam = testing::RenderTestCamera();
  const GaussianModel m = RandomScene(8, 11, 0.1, 0.3);
  const size_t np = static_cast<size_t>(cam.width) * cam.height;
  Rng rng(7);
  Image background(cam.width, cam.height, 3);
  for (size_t i = 0; i < background.size(); ++i)
    background.data()[i] = static_cast<float>(rng.Uniform(0, 1));
  std::vector<double> bg_d(background.data(), background.data() + background.size());
  GaussianRenderOptions o = Options(cam);
  o.background_image = &background;
  const double unused[3] = {0, 0, 0};
  GaussianRenderer renderer;
  GaussianRender out;
  renderer.Forward(m, o, &out);
  const testing::GaussianModelD base(m);
  const auto ref = testing::RenderGaussiansReference(base, cam, 3, true, unused, &bg_d);
  for (size_t i = 0; i < 3 * np; ++i) {
    ASSERT_NEAR(out.color.data()[i], ref.color[i], 1e-4) << i;
    ASSERT_NEAR(out.tran.data()[i], ref.tran[i], 1e-4) << i;
  }
  GaussianRenderGrad grad;
  grad.color = Image(cam.width, cam.height, 3);
  grad.tran = Image(cam.width, cam.height, 3);
  for (Image* g : {&grad.color, &grad.tran}) {
    for (size_t i = 0; i < g->size(); ++i) g->data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  }
  auto loss = [&](const testing::GaussianModelD& md, const std::vector<double>& bg) {
    const auto r = testing::RenderGaussiansReference(md, cam, 3, true, unused, &bg);
    double l = 0;
    for (size_t i = 0; i < 3 * np; ++i)
      l += grad.color.data()[i] * r.color[i] + grad.tran.data()[i] * r.tran[i];
    return l;
  };
  GaussianGradients analytic;
  renderer.Backward(m, o, out, grad, &analytic);
  testing::GaussianModelD md = base;
  int checked = 0;
  for (size_t k = 0; k < md.opacity_logits.size(); ++k) {
    const double n =
        testing::CentralDifference([&] { return loss(md, bg_d); }, &md.opacity_logits[k]);
    EXPECT_NEAR(analytic.params.opacity_logits[k], n, 1e-3 * std::abs(n) + 1e-5) << k;
    checked += std::abs(n) > 1e-3;
  }
  EXPECT_GT(checked, 2);
  // d / d background at every 7th value (all channels of many pixels).
  Image d_background;
  GaussianBackgroundGradient(out, grad, &d_background);
  double largest = 0;
  for (size_t i = 0; i < bg_d.size(); i += 7) {
    const double n = testing::CentralDifference([&] { return loss(base, bg_d); }, &bg_d[i]);
    EXPECT_NEAR(d_background.data()[i], n, 1e-4 * std::abs(n) + 1e-6) << i;
    largest = std::max(largest, std::abs(n));
  }
  EXPECT_GT(largest, 0.5);  // the background shows somewhere
}

TEST(GaussianRendererEdgeCaseTest, EmptyBehindWholeImageAndDegenerate) {
  const Camera cam = testing::RenderTestCamera(32, 32);
  const GaussianRenderOptions o = Options(cam);
  GaussianRenderer renderer;
  GaussianRender out;
  GaussianRenderGrad grad;
  grad.color = Image(32, 32, 3, 1.0f);
  grad.depth = Image(32, 32, 1, 1.0f);
  GaussianGradients g;
  auto all_finite = [](const std::vector<float>& v) {
    for (float x : v) {
      if (!std::isfinite(x)) return false;
    }
    return true;
  };
  auto check = [&](const GaussianModel& m, const char* what) {
    renderer.Forward(m, o, &out);
    for (const Image* im : {&out.color, &out.tran, &out.ref, &out.weight, &out.depth, &out.alpha}) {
      for (size_t i = 0; i < im->size(); ++i) ASSERT_TRUE(std::isfinite(im->data()[i])) << what;
    }
    renderer.Backward(m, o, out, grad, &g);
    for (const auto* v : {&g.params.means, &g.params.log_scales, &g.params.quats,
                          &g.params.opacity_logits, &g.params.sh, &g.params.ref_sh}) {
      ASSERT_TRUE(all_finite(*v)) << what;
    }
  };
  GaussianModel empty;
  check(empty, "no Gaussians");
  EXPECT_FLOAT_EQ(out.color.at(2, 5, 5), 0.7f);  // background only
  EXPECT_FLOAT_EQ(out.alpha.at(0, 5, 5), 0.0f);

  GaussianModel behind = RandomScene(10, 5);
  for (size_t i = 0; i < behind.size(); ++i)
    behind.means[3 * i + 1] = -4.0f;  // behind the camera at y = -3
  check(behind, "all behind");
  EXPECT_FLOAT_EQ(out.alpha.at(0, 16, 16), 0.0f);

  GaussianModel big = RandomScene(1, 6);
  big.means = {0, 0, 0};
  big.log_scales = {std::log(3.0f), std::log(3.0f), std::log(3.0f)};
  big.opacity_logits = {3.0f};
  check(big, "whole image");
  EXPECT_GT(out.alpha.at(0, 0, 0), 0.5f);
  EXPECT_GT(out.alpha.at(0, 31, 31), 0.5f);

  GaussianModel weird = RandomScene(6, 7);
  weird.log_scales[0] = 30.0f;   // enormous
  weird.log_scales[4] = -40.0f;  // flat to a plane
  weird.log_scales[9] = -40.0f;
  weird.log_scales[10] = -40.0f;
  weird.log_scales[11] = -40.0f;                              // a point
  for (int k = 0; k < 4; ++k) weird.quats[4 * 2 + k] = 0.0f;  // zero quaternion
  check(weird, "degenerate scales");
}

TEST(GaussianRendererThreadTest, ResultsDoNotDependOnTheThreadCount) {
  const Camera cam = testing::RenderTestCamera(64, 48);
  const GaussianModel m = RandomScene(200, 21, 0.02, 0.15);
  const GaussianRenderOptions o = Options(cam);
  GaussianRenderGrad grad;
  grad.color = Image(64, 48, 3);
  Rng rng(3);
  for (size_t i = 0; i < grad.color.size(); ++i)
    grad.color.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  // One thread, two, and two renders inside a caller's parallel region of two threads (each
  // then runs in a team smaller than omp_get_max_threads() says: the binning and the gradient
  // reduction loop over chunks and ranges, not over the team's threads).
  GaussianRender out[4];
  GaussianGradients g[4];
  const auto render = [&](int i) {
    GaussianRenderer renderer;
    renderer.Forward(m, o, &out[i]);
    renderer.Backward(m, o, out[i], grad, &g[i]);
  };
  const int saved = omp_get_max_threads();
  for (int t = 0; t < 2; ++t) {
    omp_set_num_threads(t + 1);
    render(t);
  }
#pragma omp parallel num_threads(2)
  render(2 + omp_get_thread_num());
  omp_set_num_threads(saved);
  for (int t = 1; t < 4; ++t) {
    // Forward: every pixel is computed by one thread in the same order: identical.
    for (size_t i = 0; i < out[0].color.size(); ++i)
      ASSERT_EQ(out[0].color.data()[i], out[t].color.data()[i]) << "render " << t;
    // Backward: per-tile gradients are reduced in tile order whatever the thread count:
    // identical too.
    const std::vector<ParamBlock> a = g[0].params.Blocks(), b = g[t].params.Blocks();
    for (size_t k = 0; k < a.size(); ++k) EXPECT_EQ(*a[k].data, *b[k].data) << a[k].name;
    EXPECT_EQ(g[0].mean2d, g[t].mean2d);
  }
}

// The backward skips the entries that blended no pixel (an occluded scene of opaque Gaussians).
TEST(GaussianRendererGradientTest, SkippingEntriesThatBlendedNothingChangesNoGradient) {
  const Camera cam = testing::RenderTestCamera(64, 48);
  GaussianModel m = RandomScene(300, 23, 0.05, 0.2);
  for (size_t i = 0; i < m.size(); ++i) m.opacity_logits[i] = 4.0f;  // opaque: occlusion
  GaussianRenderGrad grad;
  grad.color = testing::RandomImage(64, 48, 3, 6);
  grad.depth = testing::RandomImage(64, 48, 1, 7);
  testing::ExpectSkippedEntriesChangeNoGradient<GaussianRenderer, GaussianGradients, GaussianModel,
                                                GaussianRenderOptions, GaussianRender>(
      m, Options(cam), grad);
}

// The backward writes every gradient entry instead of adding to zeroed ones: whatever the buffers
// held before (here NaN), every row comes out as a fresh buffer's, for Gaussians out of view,
// coefficients above the current degree and the reflected colour when it is off.
TEST(GaussianRendererGradientTest, BackwardWritesEveryRowWhateverTheBuffersHeld) {
  const Camera cam = testing::RenderTestCamera(32, 32);
  GaussianModel m = RandomScene(40, 31);
  for (int i = 0; i < 5; ++i) m.means[3 * i + 2] = -50.0f;  // behind the camera: not drawn
  GaussianRenderGrad grad;
  grad.color = testing::RandomImage(32, 32, 3, 5);
  for (const bool reflection : {true, false}) {
    for (const int degree : {0, 1, 3}) {
      GaussianRenderOptions o = Options(cam, reflection);
      o.sh_degree = degree;
      GaussianRenderer renderer;
      GaussianRender out;
      renderer.Forward(m, o, &out);
      const GaussianGradients fresh =
          testing::ExpectBackwardWritesEveryRow<GaussianRenderer, GaussianGradients>(
              &renderer, m, o, out, grad,
              ", degree " + std::to_string(degree) + ", reflection " + std::to_string(reflection));
      // And a fresh buffer's rows are zero where nothing reaches them.
      for (size_t i = 0; i < 5 * fresh.params.sh.size() / m.size(); ++i) {
        ASSERT_EQ(fresh.params.sh[i], 0.0f);
        ASSERT_EQ(fresh.params.ref_sh[i], 0.0f);
      }
    }
  }
}

// Binning by the Gaussians' ellipses leaves out the tiles of their rectangles that no pixel they
// could blend lies in: the renders and the gradients are those of the whole rectangles to the bit,
// from fewer tile entries. Long thin Gaussians at random angles, large and small, on a 160 px view.
TEST(GaussianRendererGradientTest, BinningByEllipseRendersAsTheWholeRectangles) {
  const int w = 160, h = 144;
  const Camera cam = testing::RenderTestCamera(w, h);
  GaussianModel m = RandomScene(300, 43, 0.003, 0.5);
  const GaussianRenderOptions o = Options(cam);
  ProjectedGaussians p;
  ProjectGaussians(m, cam, o.sh_degree, o.reflection, &p);
  GaussianRenderGrad grad;
  grad.color = testing::RandomImage(w, h, 3, 8);
  grad.tran = testing::RandomImage(w, h, 3, 9);
  grad.depth = testing::RandomImage(w, h, 1, 10);
  grad.alpha = testing::RandomImage(w, h, 1, 11);
  const auto render = [&](const TileBins& bins) {
    RasterScratch scratch;
    GaussianRender out;
    ProjectedGaussiansGrad d;
    RasterizeGaussians(p, bins, o, &out, &scratch);
    d.Resize(p.size());
    RasterizeGaussiansBackward(p, bins, o, out, grad, &d, &scratch);
    std::string bytes;
    for (const Image* im : {&out.color, &out.tran, &out.ref, &out.weight, &out.depth, &out.alpha})
      testing::AppendBytes(*im, &bytes);
    for (const std::vector<float>* v : {&d.mean2d, &d.conic, &d.depth, &d.opacity, &d.ref_opacity,
                                        &d.beta, &d.color_t, &d.color_r})
      testing::AppendBytes(*v, &bytes);
    return bytes;
  };
  testing::ExpectEllipseBinningRendersAsTheWholeRectangles(p, w, h, 1, render);
}

// The backward reuses the rows its forward packed only for the projection that forward packed:
// handed another (here the forward's with every colour changed, which the opacities' gradients
// read), it packs that one, and its gradients are a fresh scratch's. (It writes every gradient
// entry: the buffers start as NaN, which would compare unequal.)
TEST(GaussianRendererGradientTest, BackwardPacksAProjectionItsForwardDidNot) {
  const int w = 32, h = 32;
  const Camera cam = testing::RenderTestCamera(w, h);
  const GaussianModel m = RandomScene(40, 37);
  const GaussianRenderOptions o = Options(cam);
  ProjectedGaussians p;
  ProjectGaussians(m, cam, o.sh_degree, o.reflection, &p);
  TileBins bins;
  BinPrimitives(p.rects, p.depth.data(), w, h, &bins);
  RasterScratch scratch;
  GaussianRender out;
  RasterizeGaussians(p, bins, o, &out, &scratch);
  ProjectedGaussians other = p;
  for (float& c : other.color_t) c = 1.0f - c;
  for (float& c : other.color_r) c = 1.0f - c;
  GaussianRenderGrad grad;
  grad.color = testing::RandomImage(w, h, 3, 8);
  const auto backward = [&](const ProjectedGaussians& proj, RasterScratch* s) {
    ProjectedGaussiansGrad d;  // (it holds NaN: the backward writes every entry)
    d.Resize(proj.size());
    for (auto* v : {&d.mean2d, &d.conic, &d.depth, &d.opacity, &d.ref_opacity, &d.beta, &d.color_t,
                    &d.color_r})
      std::fill(v->begin(), v->end(), std::nanf(""));
    RasterizeGaussiansBackward(proj, bins, o, out, grad, &d, s);
    return d;
  };
  const auto same = [](const ProjectedGaussiansGrad& a, const ProjectedGaussiansGrad& b) {
    return a.opacity == b.opacity && a.ref_opacity == b.ref_opacity && a.mean2d == b.mean2d &&
           a.conic == b.conic && a.color_t == b.color_t && a.color_r == b.color_r &&
           a.beta == b.beta && a.depth == b.depth;
  };
  RasterScratch fresh_scratch, fresh_scratch2;
  const ProjectedGaussiansGrad of_other = backward(other, &scratch);
  EXPECT_TRUE(same(of_other, backward(other, &fresh_scratch)));
  const ProjectedGaussiansGrad of_p = backward(p, &scratch);
  EXPECT_TRUE(same(of_p, backward(p, &fresh_scratch2)));
  EXPECT_FALSE(same(of_p, of_other));  // the colours do reach the gradients
}

}  // namespace
}  // namespace mgsr
