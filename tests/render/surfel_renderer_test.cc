#include "mgsr/render/surfel_renderer.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "mgsr/core/rng.h"
#include "mgsr/render/raster_scratch.h"
#include "reference_surfel_renderer.h"
#include "render_test_util.h"
#include "test_util.h"

namespace mgsr {
namespace {

SurfelModel RandomSurfels(int n, uint64_t seed, double scale_lo = 0.1, double scale_hi = 0.35) {
  Rng rng(seed);
  SurfelModel m;
  m.max_sh_degree = 3;
  m.Resize(n);
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) m.means[3 * i + k] = static_cast<float>(rng.Uniform(-0.6, 0.6));
    for (int k = 0; k < 2; ++k)
      m.log_scales[2 * i + k] = static_cast<float>(std::log(rng.Uniform(scale_lo, scale_hi)));
    for (int k = 0; k < 4; ++k) m.quats[4 * i + k] = static_cast<float>(rng.Normal());
    m.opacity_logits[i] = static_cast<float>(rng.Uniform(-1.0, 2.0));
  }
  for (float& v : m.sh) v = static_cast<float>(rng.Normal(0, 0.25));
  return m;
}

SurfelRenderOptions Options(const Camera& cam,
                            SurfelLowPass low_pass = SurfelLowPass::kAreaPreserving) {
  SurfelRenderOptions o;
  o.camera = cam;
  o.low_pass = low_pass;
  o.sh_degree = 3;
  o.background[0] = 0.2f;
  o.background[1] = 0.5f;
  o.background[2] = 0.7f;
  return o;
}

TEST(SurfelRendererTest, TiledRenderMatchesTheReference) {
  const double bg[3] = {0.2, 0.5, 0.7};
  for (uint64_t seed : {1, 2, 3, 4, 5, 6}) {
    // Odd seeds: the reference's full-opacity low-pass floor; even: the area-preserving one.
    const SurfelLowPass low_pass =
        seed % 2 == 1 ? SurfelLowPass::kReference : SurfelLowPass::kAreaPreserving;
    // Seeds 5 and 6: a narrower screen low-pass than the reference's.
    const float sigma = seed >= 5 ? 0.25f : kReferenceSurfelFilterSigma;
    const Camera cam = testing::RenderTestCamera(40, 36);
    const SurfelModel m = RandomSurfels(30, seed);
    SurfelRenderer renderer;
    SurfelRender out;
    SurfelRenderOptions o = Options(cam, low_pass);
    o.filter_sigma = sigma;
    renderer.Forward(m, o, &out);
    const auto ref = testing::RenderSurfelsReference(
        m, cam, 3, bg, low_pass == SurfelLowPass::kAreaPreserving, sigma);
    EXPECT_LT(testing::MaxAbsDiff(out.color, ref.color), 1e-5) << seed;
    EXPECT_LT(testing::MaxAbsDiff(out.alpha, ref.alpha), 1e-5) << seed;
    // Normals sum up to a few dozen float terms: 2e-5 (the -O1 sanitizer build, which rounds
    // differently from -O3, measured 1.1e-5 here).
    EXPECT_LT(testing::MaxAbsDiff(out.normal, ref.normal), 2e-5) << seed;
    EXPECT_LT(testing::MaxAbsDiff(out.normal_world, ref.normal_world), 2e-5) << seed;
    // Depths: relative 1e-5 (the low-pass branch takes the centre's depth, so no pixel sees the
    // ill-conditioned intersection with a nearly edge-on plane far behind the disk).
    double depth_err = 0, median_err = 0;
    for (size_t i = 0; i < out.depth.size(); ++i) {
      depth_err = std::max(depth_err, std::abs(out.depth.data()[i] - ref.depth[i]) /
                                          std::max(1.0, std::abs(ref.depth[i])));
      median_err = std::max(median_err, std::abs(out.median_depth.data()[i] - ref.median[i]) /
                                            std::max(1.0, std::abs(ref.median[i])));
    }
    EXPECT_LT(depth_err, 1e-5) << seed;
    EXPECT_LT(median_err, 1e-5) << seed;
    EXPECT_LT(testing::MaxAbsDiff(out.distortion, ref.distortion), 1e-5) << seed;
    double covered = 0;
    for (size_t i = 0; i < out.alpha.size(); ++i) covered += out.alpha.data()[i] > 0.1f;
    EXPECT_GT(covered, 0.3 * out.alpha.size());
  }
}

// Gradient of every raw parameter for an upstream gradient on each output in turn, against central
// differences of the double-precision reference.
void CheckGradients(const SurfelModel& m, const Camera& cam, const char* label,
                    bool expect_most_checked,
                    SurfelLowPass low_pass = SurfelLowPass::kAreaPreserving,
                    float filter_sigma = kReferenceSurfelFilterSigma) {
  SurfelRenderOptions o = Options(cam, low_pass);
  o.filter_sigma = filter_sigma;
  const double bg[3] = {0.2, 0.5, 0.7};
  SurfelRenderer renderer;
  SurfelRender out;
  renderer.Forward(m, o, &out);
  const size_t np = static_cast<size_t>(cam.width) * cam.height;
  const char* outputs[] = {"color",        "depth",        "alpha",     "normal",
                           "normal_world", "median_depth", "distortion"};
  for (int which = 0; which < 7; ++which) {
    Rng rng(200 + which);
    SurfelRenderGrad grad;
    Image* target[] = {&grad.color,        &grad.depth,        &grad.alpha,     &grad.normal,
                       &grad.normal_world, &grad.median_depth, &grad.distortion};
    const int channels = (which == 0 || which == 3 || which == 4) ? 3 : 1;
    *target[which] = Image(cam.width, cam.height, channels);
    // Distortion values are small; scale its upstream gradient up so the check is meaningful.
    const float scale = which == 6 ? 100.0f : 1.0f;
    for (size_t i = 0; i < target[which]->size(); ++i)
      target[which]->data()[i] = scale * static_cast<float>(rng.Uniform(-1, 1));
    const Image& upstream = *target[which];
    SurfelGradients analytic;
    renderer.Backward(m, o, out, grad, &analytic);
    auto loss = [&](const testing::SurfelModelD& md) {
      const auto r = testing::RenderSurfelsReference(
          md, cam, 3, bg, low_pass == SurfelLowPass::kAreaPreserving, filter_sigma);
      const std::vector<double>* buf[] = {&r.color,        &r.depth,  &r.alpha,     &r.normal,
                                          &r.normal_world, &r.median, &r.distortion};
      double l = 0;
      for (size_t i = 0; i < channels * np; ++i) l += upstream.data()[i] * (*buf[which])[i];
      return l;
    };
    testing::SurfelModelD base(m);
    struct Block {
      const char* name;
      std::vector<double> testing::SurfelModelD::*field;
      const std::vector<float>* analytic;
    };
    const Block blocks[] = {
        {"means", &testing::SurfelModelD::means, &analytic.params.means},
        {"log_scales", &testing::SurfelModelD::log_scales, &analytic.params.log_scales},
        {"quats", &testing::SurfelModelD::quats, &analytic.params.quats},
        {"opacity", &testing::SurfelModelD::opacity_logits, &analytic.params.opacity_logits},
        {"sh", &testing::SurfelModelD::sh, &analytic.params.sh},
    };
    // Numeric derivatives of every block first: the error floor scales with the output's largest.
    std::vector<std::vector<double>> numeric(5);
    double global_max = 0;
    for (int bi = 0; bi < 5; ++bi) {
      std::vector<double>& values = base.*(blocks[bi].field);
      numeric[bi].resize(values.size());
      for (size_t k = 0; k < values.size(); ++k) {
        const double h = 1e-6, keep = values[k];
        values[k] = keep + h;
        const double lp = loss(base);
        values[k] = keep - h;
        const double lm = loss(base);
        values[k] = keep;
        numeric[bi][k] = (lp - lm) / (2 * h);
        global_max = std::max(global_max, std::abs(numeric[bi][k]));
      }
    }
    for (int bi = 0; bi < 5; ++bi) {
      const Block& b = blocks[bi];
      double max_abs = 0;
      for (double v : numeric[bi]) max_abs = std::max(max_abs, std::abs(v));
      int checked = 0;
      for (size_t k = 0; k < numeric[bi].size(); ++k) {
        const double a = (*b.analytic)[k], n = numeric[bi][k];
        // Relative 1e-3 where the derivative is not tiny; float rounding allows a floor of 1e-5 of
        // the output's largest derivative (exact zeros come out as ~1e-7 in float).
        const double tol = 1e-3 * std::abs(n) + 1e-4 * max_abs + 1e-5 * global_max + 1e-7;
        EXPECT_NEAR(a, n, tol) << label << ": " << outputs[which] << " d/d " << b.name << "[" << k
                               << "]";
        checked += std::abs(n) > 1e-4 * max_abs;
      }
      if (expect_most_checked && max_abs > 1e-3 * global_max) {
        EXPECT_GT(checked, static_cast<int>(numeric[bi].size()) / 4)
            << outputs[which] << " " << b.name;
      }
    }
  }
}

// A background per pixel (a learnt environment): the render matches the reference, the surfels'
// gradients still match numeric differentiation, and d loss / d background is T_N times the colour
// gradient (SurfelBackgroundGradient), checked numerically too.
TEST(SurfelRendererGradientTest, PerPixelBackgroundMatchesNumericDifferentiation) {
  const Camera cam = testing::RenderTestCamera();
  const SurfelModel m = RandomSurfels(8, 5);
  const size_t np = static_cast<size_t>(cam.width) * cam.height;
  Rng rng(9);
  Image background(cam.width, cam.height, 3);
  for (size_t i = 0; i < background.size(); ++i)
    background.data()[i] = static_cast<float>(rng.Uniform(0, 1));
  std::vector<double> bg_d(background.data(), background.data() + background.size());
  SurfelRenderOptions o = Options(cam);
  o.background_image = &background;
  const double unused[3] = {0, 0, 0};
  SurfelRenderer renderer;
  SurfelRender out;
  renderer.Forward(m, o, &out);
  const testing::SurfelModelD base(m);
  const auto ref = testing::RenderSurfelsReference(base, cam, 3, unused, true,
                                                   kReferenceSurfelFilterSigma, &bg_d);
  for (size_t i = 0; i < 3 * np; ++i) ASSERT_NEAR(out.color.data()[i], ref.color[i], 1e-4) << i;
  SurfelRenderGrad grad;
  grad.color = Image(cam.width, cam.height, 3);
  for (size_t i = 0; i < grad.color.size(); ++i)
    grad.color.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  auto loss = [&](const testing::SurfelModelD& md, const std::vector<double>& bg) {
    const auto r =
        testing::RenderSurfelsReference(md, cam, 3, unused, true, kReferenceSurfelFilterSigma, &bg);
    double l = 0;
    for (size_t i = 0; i < 3 * np; ++i) l += grad.color.data()[i] * r.color[i];
    return l;
  };
  SurfelGradients analytic;
  renderer.Backward(m, o, out, grad, &analytic);
  testing::SurfelModelD md = base;
  int checked = 0;
  for (size_t k = 0; k < md.opacity_logits.size(); ++k) {
    const double n =
        testing::CentralDifference([&] { return loss(md, bg_d); }, &md.opacity_logits[k]);
    EXPECT_NEAR(analytic.params.opacity_logits[k], n, 1e-3 * std::abs(n) + 1e-5) << k;
    checked += std::abs(n) > 1e-3;
  }
  EXPECT_GT(checked, 2);
  Image d_background;
  SurfelBackgroundGradient(out, grad, &d_background);
  double largest = 0;
  for (size_t i = 0; i < bg_d.size(); i += 7) {
    const double n = testing::CentralDifference([&] { return loss(base, bg_d); }, &bg_d[i]);
    EXPECT_NEAR(d_background.data()[i], n, 1e-4 * std::abs(n) + 1e-6) << i;
    largest = std::max(largest, std::abs(n));
  }
  EXPECT_GT(largest, 0.5);
}

// Recording contributions leaves the render bitwise unchanged, and the per-surfel sums add up to
// the image's summed blend weights; a surfel behind the camera contributes nothing.
TEST(SurfelRendererTest, ContributionsSumToTheBlendedWeights) {
  const Camera cam = testing::RenderTestCamera(40, 36);
  SurfelModel m = RandomSurfels(30, 6);
  m.means[1] = -6.0f;  // behind the camera (at y = -3, looking along +y)
  SurfelRenderer renderer;
  SurfelRender plain, recorded;
  SurfelRenderOptions o = Options(cam);
  renderer.Forward(m, o, &plain);
  EXPECT_TRUE(plain.contribution.empty());
  o.record_contribution = true;
  renderer.Forward(m, o, &recorded);
  EXPECT_TRUE(std::equal(plain.depth.data(), plain.depth.data() + plain.depth.size(),
                         recorded.depth.data()));
  ASSERT_EQ(recorded.contribution.size(), m.size());
  double sum = 0, expected = 0;
  for (float c : recorded.contribution) sum += c;
  for (float w : recorded.weight_sum) expected += w;
  EXPECT_NEAR(sum, expected, 1e-4 * expected);
  EXPECT_GT(expected, 100.0);
  EXPECT_EQ(recorded.contribution[0], 0.0f);
}

// Without the distortion (what training renders when no loss row reads it) the distortion image
// is absent, every other output and every gradient through them is the same to the bit, and a
// distortion gradient is ignored; with it, that gradient reaches the surfels.
TEST(SurfelRendererTest, SkippingTheDistortionChangesNothingElse) {
  const Camera cam = testing::RenderTestCamera(40, 36);
  const SurfelModel m = RandomSurfels(30, 7);
  SurfelRenderOptions on = Options(cam), off = on;
  off.distortion = false;
  Rng rng(3);
  auto random_image = [&](int channels) {
    Image im(cam.width, cam.height, channels);
    for (size_t i = 0; i < im.size(); ++i) im.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
    return im;
  };
  SurfelRenderGrad grad;
  grad.color = random_image(3);
  grad.normal_world = random_image(3);
  grad.depth = random_image(1);
  grad.alpha = random_image(1);
  grad.median_depth = random_image(1);
  SurfelRenderGrad with_distortion = grad;
  with_distortion.distortion = random_image(1);

  SurfelRenderer renderer;
  SurfelRender with, without;
  SurfelGradients g_on, g_on_distortion, g_off, g_off_distortion;
  renderer.Forward(m, on, &with);
  renderer.Backward(m, on, with, grad, &g_on);
  renderer.Backward(m, on, with, with_distortion, &g_on_distortion);
  renderer.Forward(m, off, &without);
  renderer.Backward(m, off, without, grad, &g_off);
  renderer.Backward(m, off, without, with_distortion, &g_off_distortion);

  EXPECT_TRUE(without.distortion.empty());
  float largest = 0;
  for (size_t i = 0; i < with.distortion.size(); ++i)
    largest = std::max(largest, std::abs(with.distortion.data()[i]));
  EXPECT_GT(largest, 0.0f);
  for (auto image :
       {&SurfelRender::color, &SurfelRender::depth, &SurfelRender::alpha, &SurfelRender::normal,
        &SurfelRender::normal_world, &SurfelRender::median_depth}) {
    const Image& a = with.*image;
    const Image& b = without.*image;
    ASSERT_EQ(a.size(), b.size());
    EXPECT_TRUE(std::equal(a.data(), a.data() + a.size(), b.data()));
  }
  const auto same = [](SurfelGradients& a, SurfelGradients& b) {
    const std::vector<ParamBlock> x = a.params.Blocks(), y = b.params.Blocks();
    for (size_t k = 0; k < x.size(); ++k)
      if (*x[k].data != *y[k].data) return false;
    return true;
  };
  EXPECT_TRUE(same(g_on, g_off));
  EXPECT_TRUE(same(g_off, g_off_distortion));
  EXPECT_FALSE(same(g_on, g_on_distortion));
}

// The backward skips the entries that blended no pixel (an occluded scene of opaque surfels).
TEST(SurfelRendererTest, SkippingEntriesThatBlendedNothingChangesNoGradient) {
  const Camera cam = testing::RenderTestCamera(64, 48);
  SurfelModel m = RandomSurfels(200, 9, 0.1, 0.3);
  for (size_t i = 0; i < m.size(); ++i) m.opacity_logits[i] = 4.0f;  // opaque: occlusion
  SurfelRenderGrad grad;
  grad.color = testing::RandomImage(64, 48, 3, 7);
  grad.depth = testing::RandomImage(64, 48, 1, 8);
  grad.median_depth = testing::RandomImage(64, 48, 1, 9);
  testing::ExpectSkippedEntriesChangeNoGradient<SurfelRenderer, SurfelGradients, SurfelModel,
                                                SurfelRenderOptions, SurfelRender>(m, Options(cam),
                                                                                   grad);
}

// One, two threads and a render inside another parallel region (a team smaller than
// omp_get_max_threads() says): the same images and gradients to the bit.
TEST(SurfelRendererTest, ResultsDoNotDependOnTheThreadsOrAnEnclosingParallelRegion) {
  const Camera cam = testing::RenderTestCamera(64, 48);
  const SurfelModel m = RandomSurfels(120, 8, 0.05, 0.2);
  const SurfelRenderOptions o = Options(cam);
  SurfelRenderGrad grad;
  grad.color = Image(cam.width, cam.height, 3);
  grad.depth = Image(cam.width, cam.height, 1);
  Rng rng(5);
  for (Image* im : {&grad.color, &grad.depth})
    for (size_t i = 0; i < im->size(); ++i) im->data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  const auto render = [&](SurfelRender* out, SurfelGradients* g) {
    SurfelRenderer renderer;
    renderer.Forward(m, o, out);
    renderer.Backward(m, o, *out, grad, g);
  };
  const int saved = omp_get_max_threads();
  SurfelRender out[4];
  SurfelGradients g[4];
  for (int t = 0; t < 2; ++t) {
    omp_set_num_threads(t + 1);
    render(&out[t], &g[t]);
  }
#pragma omp parallel num_threads(2)
  render(&out[2 + omp_get_thread_num()], &g[2 + omp_get_thread_num()]);
  omp_set_num_threads(saved);
  for (int t = 1; t < 4; ++t) {
    for (auto image : {&SurfelRender::color, &SurfelRender::depth, &SurfelRender::normal}) {
      const Image& a = out[0].*image;
      const Image& b = out[t].*image;
      ASSERT_EQ(a.size(), b.size());
      EXPECT_TRUE(std::equal(a.data(), a.data() + a.size(), b.data())) << "render " << t;
    }
    const std::vector<ParamBlock> x = g[0].params.Blocks(), y = g[t].params.Blocks();
    for (size_t k = 0; k < x.size(); ++k) EXPECT_EQ(*x[k].data, *y[k].data) << x[k].name;
  }
}

TEST(SurfelRendererGradientTest, AllParametersAllOutputsMatchNumericDifferentiation) {
  CheckGradients(RandomSurfels(8, 11, 0.15, 0.35), testing::RenderTestCamera(), "splats", true);
}

// Surfels far smaller than a pixel: the screen low-pass floor (rho2d < rho3d) decides their
// footprint almost everywhere, so this checks that branch, including the gradient through the
// screen centre.
TEST(SurfelRendererGradientTest, LowPassBranchMatchesNumericDifferentiation) {
  SurfelModel m = RandomSurfels(6, 12, 0.002, 0.004);
  for (size_t i = 0; i < m.size(); ++i) m.opacity_logits[i] = 2.0f;
  CheckGradients(m, testing::RenderTestCamera(), "low-pass", false, SurfelLowPass::kReference);
}

// Surfels of a fraction of a pixel (about 0.2-0.6 px at this camera), some nearly edge-on: the
// area-preserving floor's opacity min(1, 2 |det J|) is below one, so its gradient through det M
// (scales, rotation, position, depth) is exercised beside the splat branch.
TEST(SurfelRendererGradientTest, AreaPreservingLowPassMatchesNumericDifferentiation) {
  SurfelModel m = RandomSurfels(8, 13, 0.02, 0.06);
  for (size_t i = 0; i < m.size(); ++i) m.opacity_logits[i] = 2.0f;
  CheckGradients(m, testing::RenderTestCamera(), "area-preserving low-pass", false);
}

// A narrower screen low-pass (sigma 0.3 px, both floors): the filter's width enters rho2d, the
// area-preserving floor's opacity and the screen radius.
TEST(SurfelRendererGradientTest, NarrowLowPassMatchesNumericDifferentiation) {
  SurfelModel m = RandomSurfels(8, 13, 0.02, 0.06);
  for (size_t i = 0; i < m.size(); ++i) m.opacity_logits[i] = 2.0f;
  CheckGradients(m, testing::RenderTestCamera(), "narrow area-preserving low-pass", false,
                 SurfelLowPass::kAreaPreserving, 0.3f);
  SurfelModel tiny = RandomSurfels(6, 12, 0.002, 0.004);
  for (size_t i = 0; i < tiny.size(); ++i) tiny.opacity_logits[i] = 2.0f;
  CheckGradients(tiny, testing::RenderTestCamera(), "narrow low-pass", false,
                 SurfelLowPass::kReference, 0.3f);
}

TEST(SurfelRendererGeometryTest, FlatSplatFacingTheCamera) {
  const Camera cam = LookAtCamera({0, -3, 0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 32, 32, 40, 40);
  SurfelModel m;
  m.max_sh_degree = 0;
  m.Resize(1);
  m.means = {0, 0, 0};
  m.log_scales = {std::log(0.5f), std::log(0.5f)};
  // Rotate local z (the normal) onto -y: a quarter turn about x.
  const Eigen::Quaternionf q(
      Eigen::AngleAxisf(static_cast<float>(M_PI / 2), Eigen::Vector3f::UnitX()));
  m.quats = {q.w(), q.x(), q.y(), q.z()};
  m.opacity_logits = {5.0f};
  m.sh = {0.1f, 0.2f, 0.3f};
  SurfelRenderer renderer;
  SurfelRender out;
  renderer.Forward(m, Options(cam), &out);
  // Every covered pixel sees the plane y = 0 at view depth exactly 3; the normal faces the camera.
  int covered = 0;
  for (int y = 0; y < 32; ++y) {
    for (int x = 0; x < 32; ++x) {
      if (out.alpha.at(0, y, x) < 0.5f) continue;
      ++covered;
      EXPECT_NEAR(out.depth.at(0, y, x), 3.0f, 1e-5f);
      const float a = out.alpha.at(0, y, x);
      EXPECT_NEAR(out.normal.at(2, y, x) / a, -1.0f, 1e-5f);  // view space: towards the camera
      EXPECT_NEAR(out.normal_world.at(1, y, x) / a, -1.0f, 1e-5f);  // world: towards -y
    }
  }
  EXPECT_GT(covered, 50);
  // The centre pixels are nearly opaque (o = sigmoid(5) ~ 0.993, clamped at 0.99; their centres
  // are half a pixel from the splat's centre).
  EXPECT_GT(out.alpha.at(0, 16, 16), 0.98f);
  EXPECT_LE(out.alpha.at(0, 16, 16), 0.99f);
}

// A disk seen almost edge-on covers less than a pixel row; the screen low-pass draws it around its
// centre, on pixels whose rays meet its plane far from the disk (behind the camera at 0.01 degrees
// from edge-on, 1.2 units in front of the disk at 0.5). Those pixels take the centre's depth, so
// every depth stays on the disk.
TEST(SurfelRendererGeometryTest, NearlyEdgeOnSplatKeepsItsDepthOnTheDisk) {
  const Camera cam = LookAtCamera({0, -3, 0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 32, 32, 40, 40);
  for (double degrees : {0.01, 0.5, 5.0}) {
    SurfelModel m;
    m.max_sh_degree = 0;
    m.Resize(1);
    m.means = {0, 0, 0};
    m.log_scales = {std::log(0.3f), std::log(0.3f)};
    // Normal along z, tilted towards the camera (-y) by the given angle: the disk lies almost in
    // the plane through the viewing direction.
    const Eigen::Quaternionf q(
        Eigen::AngleAxisf(static_cast<float>(degrees * M_PI / 180), Eigen::Vector3f::UnitX()));
    m.quats = {q.w(), q.x(), q.y(), q.z()};
    m.opacity_logits = {5.0f};
    m.sh = {0.1f, 0.2f, 0.3f};
    SurfelRenderer renderer;
    SurfelRender out;
    renderer.Forward(m, Options(cam, SurfelLowPass::kReference), &out);
    int drawn = 0;
    for (int y = 0; y < 32; ++y) {
      for (int x = 0; x < 32; ++x) {
        if (out.alpha.at(0, y, x) < 0.05f) continue;
        ++drawn;
        // The disk spans view depths 3 +- 3 sigma = 3 +- 0.9.
        EXPECT_GT(out.depth.at(0, y, x), 2.0f) << degrees << " " << x << "," << y;
        EXPECT_LT(out.depth.at(0, y, x), 4.0f) << degrees << " " << x << "," << y;
        EXPECT_GT(out.median_depth.at(0, y, x), 2.0f) << degrees << " " << x << "," << y;
        EXPECT_LT(out.median_depth.at(0, y, x), 4.0f) << degrees << " " << x << "," << y;
      }
    }
    EXPECT_GE(drawn, 8) << degrees;  // the low-pass footprint around the centre is drawn
  }
}

TEST(SurfelRendererGeometryTest, PlaneOfOverlappingSplatsGivesConstantNormalAndExactDepth) {
  const Camera cam =
      LookAtCamera({0.5, -3, 1.0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 48, 48, 60, 60);
  // The plane through the origin with normal n; surfels on a grid in it, all with that normal.
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -1, 0.3).normalized();
  const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
  Eigen::Matrix3d R;
  R << e1, e2, n;
  const Eigen::Quaterniond q(R);
  SurfelModel m;
  m.max_sh_degree = 0;
  const int g = 15;
  m.Resize(g * g);
  for (int i = 0; i < g; ++i) {
    for (int j = 0; j < g; ++j) {
      const int k = i * g + j;
      const Eigen::Vector3d p = (i - g / 2) * 0.1 * e1 + (j - g / 2) * 0.1 * e2;
      for (int d = 0; d < 3; ++d) m.means[3 * k + d] = static_cast<float>(p[d]);
      m.log_scales[2 * k] = m.log_scales[2 * k + 1] = std::log(0.1f);
      m.quats[4 * k] = static_cast<float>(q.w());
      m.quats[4 * k + 1] = static_cast<float>(q.x());
      m.quats[4 * k + 2] = static_cast<float>(q.y());
      m.quats[4 * k + 3] = static_cast<float>(q.z());
      m.opacity_logits[k] = 3.0f;
      m.sh[3 * k] = m.sh[3 * k + 1] = m.sh[3 * k + 2] = 0.0f;
    }
  }
  SurfelRenderer renderer;
  SurfelRender out;
  renderer.Forward(m, Options(cam), &out);
  const Eigen::Vector3d n_facing = n.dot(cam.Center()) > 0 ? n : Eigen::Vector3d(-n);
  int checked = 0;
  for (int y = 8; y < 40; ++y) {
    for (int x = 8; x < 40; ++x) {
      const float a = out.alpha.at(0, y, x);
      if (a < 0.99f) continue;
      ++checked;
      // Ray-plane intersection at the pixel centre.
      const Eigen::Vector3d ray = cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5);
      const double t = -n.dot(cam.Center()) / n.dot(ray);
      EXPECT_NEAR(out.depth.at(0, y, x), t, 1e-4)
          << x << "," << y;  // ray has camera z = 1: t is the depth
      const Eigen::Vector3d nw(out.normal_world.at(0, y, x) / a, out.normal_world.at(1, y, x) / a,
                               out.normal_world.at(2, y, x) / a);
      EXPECT_NEAR((nw - n_facing).norm(), 0.0, 1e-4) << x << "," << y;
    }
  }
  EXPECT_GT(checked, 400);
}

TEST(SurfelRendererEdgeCaseTest, EmptyBehindWholeImageAndDegenerate) {
  const Camera cam = testing::RenderTestCamera(32, 32);
  const SurfelRenderOptions o = Options(cam);
  SurfelRenderer renderer;
  SurfelRender out;
  SurfelRenderGrad grad;
  grad.color = Image(32, 32, 3, 1.0f);
  grad.depth = Image(32, 32, 1, 1.0f);
  grad.normal_world = Image(32, 32, 3, 1.0f);
  grad.distortion = Image(32, 32, 1, 1.0f);
  SurfelGradients gr;
  auto check = [&](const SurfelModel& m, const char* what) {
    renderer.Forward(m, o, &out);
    for (const Image* im :
         {&out.color, &out.depth, &out.alpha, &out.normal, &out.median_depth, &out.distortion}) {
      for (size_t i = 0; i < im->size(); ++i) ASSERT_TRUE(std::isfinite(im->data()[i])) << what;
    }
    renderer.Backward(m, o, out, grad, &gr);
    for (const auto* v : {&gr.params.means, &gr.params.log_scales, &gr.params.quats,
                          &gr.params.opacity_logits, &gr.params.sh}) {
      for (float x : *v) ASSERT_TRUE(std::isfinite(x)) << what;
    }
  };
  check(SurfelModel(), "no surfels");
  EXPECT_FLOAT_EQ(out.color.at(2, 3, 3), 0.7f);
  SurfelModel behind = RandomSurfels(10, 5);
  for (size_t i = 0; i < behind.size(); ++i) behind.means[3 * i + 1] = -4.0f;
  check(behind, "all behind");
  EXPECT_FLOAT_EQ(out.alpha.at(0, 16, 16), 0.0f);
  SurfelModel big = RandomSurfels(1, 6);
  big.means = {0, 0, 0};
  big.log_scales = {std::log(5.0f), std::log(5.0f)};
  big.quats = {0.7071f, 0.7071f, 0, 0};
  big.opacity_logits = {3.0f};
  check(big, "whole image");
  EXPECT_GT(out.alpha.at(0, 0, 0), 0.5f);
  EXPECT_GT(out.alpha.at(0, 31, 31), 0.5f);
  SurfelModel weird = RandomSurfels(6, 7);
  weird.log_scales[0] = 30.0f;
  weird.log_scales[2] = -40.0f;
  weird.log_scales[3] = -40.0f;
  for (int k = 0; k < 4; ++k) weird.quats[4 * 4 + k] = 0.0f;
  check(weird, "degenerate");
}

// The backward writes every gradient entry instead of adding to zeroed ones: whatever the buffers
// held before (here NaN), every row comes out as a fresh buffer's, for surfels out of view and
// coefficients above the current degree.
TEST(SurfelRendererTest, BackwardWritesEveryRowWhateverTheBuffersHeld) {
  const Camera cam = testing::RenderTestCamera(32, 32);
  SurfelModel m = RandomSurfels(40, 31);
  for (int i = 0; i < 5; ++i) m.means[3 * i + 2] = -50.0f;  // behind the camera: not drawn
  SurfelRenderGrad grad;
  grad.color = testing::RandomImage(32, 32, 3, 5);
  for (const int degree : {0, 1, 3}) {
    SurfelRenderOptions o = Options(cam);
    o.sh_degree = degree;
    SurfelRenderer renderer;
    SurfelRender out;
    renderer.Forward(m, o, &out);
    const SurfelGradients fresh =
        testing::ExpectBackwardWritesEveryRow<SurfelRenderer, SurfelGradients>(
            &renderer, m, o, out, grad, ", degree " + std::to_string(degree));
    for (size_t i = 0; i < 5 * fresh.params.sh.size() / m.size(); ++i)
      ASSERT_EQ(fresh.params.sh[i], 0.0f);
  }
}

// Binning by the surfels' ellipses (the disk's image and the low-pass circle) leaves out the
// tiles of their rectangles that no pixel they could blend lies in: the renders and gradients are
// those of the whole rectangles to the bit, from fewer tile entries. Disks at random angles (many
// seen nearly edge-on), large and small, on a 160 px view; both low-pass forms.
TEST(SurfelRendererTest, BinningByEllipseRendersAsTheWholeRectangles) {
  const int w = 160, h = 144;
  const Camera cam = testing::RenderTestCamera(w, h);
  const SurfelModel m = RandomSurfels(300, 17, 0.005, 0.6);
  for (const SurfelLowPass low_pass : {SurfelLowPass::kAreaPreserving, SurfelLowPass::kReference}) {
    SurfelRenderOptions o = Options(cam, low_pass);
    o.distortion = true;
    ProjectedSurfels p;
    ProjectSurfels(m, cam, o.sh_degree, &p, o.filter_sigma);
    SurfelRenderGrad grad;
    grad.color = testing::RandomImage(w, h, 3, 8);
    grad.depth = testing::RandomImage(w, h, 1, 9);
    grad.alpha = testing::RandomImage(w, h, 1, 10);
    grad.normal_world = testing::RandomImage(w, h, 3, 11);
    grad.median_depth = testing::RandomImage(w, h, 1, 12);
    grad.distortion = testing::RandomImage(w, h, 1, 13);
    const auto render = [&](const TileBins& bins) {
      RasterScratch scratch;
      SurfelRender out;
      ProjectedSurfelsGrad d;
      RasterizeSurfels(p, bins, o, &out, &scratch);
      d.Resize(p.size());
      RasterizeSurfelsBackward(p, bins, o, out, grad, &d, &scratch);
      std::string bytes;
      for (const Image* im : {&out.color, &out.depth, &out.alpha, &out.normal_world,
                              &out.median_depth, &out.distortion})
        testing::AppendBytes(*im, &bytes);
      for (const std::vector<float>* v : {&d.M, &d.center, &d.normal, &d.opacity, &d.color})
        testing::AppendBytes(*v, &bytes);
      return bytes;
    };
    testing::ExpectEllipseBinningRendersAsTheWholeRectangles(p, w, h, 2, render);
  }
}

// The backward reuses the rows its forward packed, computing only the low-pass offsets' gradients
// (d c / d M), for the projection that forward packed, and packs any other (here the forward's
// with every colour changed): both give a fresh scratch's gradients. Small surfels, so the
// area-preserving offsets reach the gradients. (It writes every gradient entry: the buffers start
// as NaN, which would compare unequal.)
TEST(SurfelRendererTest, BackwardPacksAProjectionItsForwardDidNot) {
  const int w = 32, h = 32;
  const Camera cam = testing::RenderTestCamera(w, h);
  const SurfelModel m = RandomSurfels(40, 14, 0.01, 0.2);
  const SurfelRenderOptions o = Options(cam);
  ProjectedSurfels p;
  ProjectSurfels(m, cam, o.sh_degree, &p, o.filter_sigma);
  TileBins bins;
  BinPrimitives(p.rects, p.depth.data(), w, h, &bins);
  RasterScratch scratch;
  SurfelRender out;
  RasterizeSurfels(p, bins, o, &out, &scratch);
  ProjectedSurfels other = p;
  for (float& c : other.color) c = 1.0f - c;
  SurfelRenderGrad grad;
  grad.color = testing::RandomImage(w, h, 3, 8);
  grad.depth = testing::RandomImage(w, h, 1, 9);
  const auto backward = [&](const ProjectedSurfels& proj, RasterScratch* s) {
    ProjectedSurfelsGrad d;  // (it holds NaN: the backward writes every entry)
    d.Resize(proj.size());
    for (auto* v : {&d.M, &d.center, &d.normal, &d.opacity, &d.color})
      std::fill(v->begin(), v->end(), std::nanf(""));
    RasterizeSurfelsBackward(proj, bins, o, out, grad, &d, s);
    return d;
  };
  const auto same = [](const ProjectedSurfelsGrad& a, const ProjectedSurfelsGrad& b) {
    return a.M == b.M && a.center == b.center && a.normal == b.normal && a.opacity == b.opacity &&
           a.color == b.color;
  };
  RasterScratch fresh_scratch, fresh_scratch2;
  const ProjectedSurfelsGrad of_p = backward(p, &scratch);  // the forward's rows
  EXPECT_TRUE(same(of_p, backward(p, &fresh_scratch)));
  const ProjectedSurfelsGrad of_other = backward(other, &scratch);
  EXPECT_TRUE(same(of_other, backward(other, &fresh_scratch2)));
  EXPECT_FALSE(same(of_p, of_other));  // the colours do reach the gradients
}

}  // namespace
}  // namespace mgsr
