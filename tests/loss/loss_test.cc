#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>
#include <vector>

#include "mgsr/core/rng.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/loss/dssim_loss.h"
#include "mgsr/loss/dssim_plane.h"
#include "mgsr/loss/edge_aware_tv_loss.h"
#include "mgsr/loss/edge_aware_tv_plane.h"
#include "mgsr/loss/exposure_compensation.h"
#include "mgsr/loss/l1_loss.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/loss/mask_loss.h"
#include "mgsr/loss/multiview_ncc_loss.h"
#include "mgsr/loss/mutual_depth_loss.h"
#include "mgsr/loss/normal_consistency_loss.h"
#include "mgsr/loss/normal_consistency_plane.h"
#include "mgsr/loss/problem.h"
#include "mgsr/loss/render_loss.h"
#include "test_util.h"

namespace mgsr {
namespace {

// Random double-precision inputs for any term: every buffer and every target, plausible ranges
// (positive depths around 3, alpha in (0.5, 1)), and for the multi-view terms a grey photo and two
// neighbours a little to the side with their own photos and depths.
struct Fixture {
  Camera camera = LookAtCamera({0.2, -3, 0.5}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 14, 11, 16, 16);
  std::array<Camera, 2> neighbour_cameras = {
      LookAtCamera({0.45, -2.95, 0.55}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 14, 11, 16, 16),
      LookAtCamera({0.05, -3.02, 0.3}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 14, 11, 16, 16)};
  std::array<ImageD, kNumBuffers> buffers;
  ImageD image, transmitted, mask, other_depth, gray;
  std::array<ImageD, 2> neighbour_gray, neighbour_depth;
  RenderBuffersD in;
  TargetsD targets;

  explicit Fixture(uint64_t seed) {
    Rng rng(seed);
    const int w = camera.width, h = camera.height;
    auto random = [&](int c, double lo, double hi) {
      ImageD im(w, h, c);
      for (size_t i = 0; i < im.size(); ++i) im.data()[i] = rng.Uniform(lo, hi);
      return im;
    };
    for (int b = 0; b < kNumBuffers; ++b) {
      const Buffer buf = static_cast<Buffer>(b);
      if (buf == Buffer::kDepth || buf == Buffer::kMedianDepth)
        buffers[b] = random(1, 2.8, 3.2);
      else if (buf == Buffer::kAlpha)
        buffers[b] = random(1, 0.5, 1.0);
      else
        buffers[b] = random(BufferChannels(buf), -0.2, 1.2);
      in.Set(buf, &buffers[b]);
    }
    in.camera = &camera;
    image = random(3, 0, 1);
    transmitted = random(3, 0, 1);
    mask = random(1, 0, 1);
    other_depth = random(1, 2.5, 3.5);
    targets.image = &image;
    targets.transmitted = &transmitted;
    targets.mask = &mask;
    targets.other_depth = &other_depth;
    gray = random(1, 0, 1);
    targets.gray = &gray;
    for (int k = 0; k < 2; ++k) {
      neighbour_gray[k] = random(1, 0, 1);
      neighbour_depth[k] = random(1, 2.9, 3.1);
      targets.neighbours[k] = {&neighbour_cameras[k], &neighbour_gray[k], &neighbour_depth[k]};
    }
    targets.num_neighbours = 2;
  }
};

// The generic harness: every input buffer element of `term`, analytic against central differences.
// Constant inputs (stop-gradient) are not differentiated. The mutual depth holds its maxima
// constant by design, so the harness skips the one pixel where that differs (the argmax).
void ExpectGradientMatchesNumeric(const LossTerm& term, uint64_t seed = 1) {
  SCOPED_TRACE(term.Name());
  Fixture f(seed);
  RenderGradientsD grad;
  const double scale = 1.7;
  const double value = term.Evaluate(f.in, f.targets, scale, &grad);
  EXPECT_TRUE(std::isfinite(value));
  int nonzero = 0;
  for (Buffer b : term.Inputs()) {
    ImageD& x = f.buffers[static_cast<int>(b)];
    const ImageD& g = grad.Get(b);
    const bool has_grad = !g.empty();
    const size_t argmax = std::max_element(x.data(), x.data() + x.size()) - x.data();
    const bool skip_argmax = term.Name().rfind("mutual_depth", 0) == 0;
    for (size_t i = 0; i < x.size(); ++i) {
      if (skip_argmax && i == argmax) continue;
      const double keep = x.data()[i], h = 1e-6;
      x.data()[i] = keep + h;
      const double vp = term.Evaluate(f.in, f.targets, 1.0, nullptr);
      x.data()[i] = keep - h;
      const double vm = term.Evaluate(f.in, f.targets, 1.0, nullptr);
      x.data()[i] = keep;
      const double numeric = scale * (vp - vm) / (2 * h);
      const double analytic = has_grad ? g.data()[i] : 0.0;
      EXPECT_NEAR(analytic, numeric, 1e-6 + 1e-5 * std::abs(numeric))
          << BufferName(b) << "[" << i << "]";
      nonzero += std::abs(numeric) > 1e-9;
    }
  }
  EXPECT_GT(nonzero, 0) << "the term should depend on its inputs";
}

NormalConsistencyOptions NcOptions(bool depth_gradient, double edge_weight, double robust_scale,
                                   bool one_sided) {
  NormalConsistencyOptions o;
  o.depth_gradient = depth_gradient;
  o.edge_weight = edge_weight;
  o.robust_scale = robust_scale;
  o.one_sided = one_sided;
  return o;
}

TEST(LossGradientTest, EveryTermMatchesNumericDifferentiation) {
  ExpectGradientMatchesNumeric(L1Loss(Buffer::kColor, TargetKind::kImage));
  ExpectGradientMatchesNumeric(L1Loss(Buffer::kTransmitted, TargetKind::kTransmitted));
  ExpectGradientMatchesNumeric(DssimLoss(Buffer::kColor, TargetKind::kImage));
  ExpectGradientMatchesNumeric(RenderLoss(Buffer::kColor, TargetKind::kImage, 0.8));
  ExpectGradientMatchesNumeric(MutualRenderLoss());
  // The normal consistency relaxed at the photo's edges, and without its pull on the depth.
  ExpectGradientMatchesNumeric(NormalConsistencyLoss(NcOptions(true, 5.0, 0, false)));
  ExpectGradientMatchesNumeric(NormalConsistencyLoss(NcOptions(false, 0, 0, false)));
  // Bounded residuals: at a small scale most pixels lie on the flat part of rho.
  ExpectGradientMatchesNumeric(NormalConsistencyLoss(NcOptions(true, 0, 0.1, false)));
  ExpectGradientMatchesNumeric(NormalConsistencyLoss(NcOptions(true, 5.0, 0.02, false)));
  // One-sided differences (the fixture's depths are random, so both sides are taken).
  ExpectGradientMatchesNumeric(NormalConsistencyLoss(NcOptions(true, 0, 0, true)));
  ExpectGradientMatchesNumeric(NormalConsistencyLoss(NcOptions(true, 0, 0.1, true)), 5);
  ExpectGradientMatchesNumeric(MultiviewNccLoss([] {
    MultiviewNccConfig c;
    c.check_occlusion = false;
    c.patch_radius = 2;
    c.stride = 2;
    c.max_plane_offset_px = 0;  // random depths lie on no plane (multiview_test: on a plane)
    c.max_pair_loss = 2;        // random patches: keep every pair (multiview_test: the outliers)
    return c;
  }()));
  ExpectGradientMatchesNumeric(EdgeAwareTvLoss(Buffer::kTransmitted, TargetKind::kImage));
  ExpectGradientMatchesNumeric(EdgeAwareTvLoss(Buffer::kDepth, TargetKind::kTransmitted));
  ExpectGradientMatchesNumeric(EdgeAwareTvLoss(Buffer::kNormal, TargetKind::kImage));
  ExpectGradientMatchesNumeric(EdgeAwareTvLoss(Buffer::kDepth, TargetKind::kImage, true));
  ExpectGradientMatchesNumeric(
      EdgeAwareTvLoss(Buffer::kDepth, TargetKind::kTransmitted, false, 2.5));
  ExpectGradientMatchesNumeric(EdgeAwareTvLoss(Buffer::kDepth, TargetKind::kImage, true, 4.0));
  ExpectGradientMatchesNumeric(NormalConsistencyLoss());
  ExpectGradientMatchesNumeric(NormalConsistencyLoss(), 5);
  ExpectGradientMatchesNumeric(MutualDepthLoss(false));
  ExpectGradientMatchesNumeric(MutualDepthLoss(true));
  ExpectGradientMatchesNumeric(DistortionLoss());
  ExpectGradientMatchesNumeric(MaskLoss());
  ExpectGradientMatchesNumeric(MaskLoss(false));
  ExpectGradientMatchesNumeric(ExposureCompensatedLoss(
      std::make_unique<RenderLoss>(Buffer::kColor, TargetKind::kImage, 0.8),
      {1.3, 0.1, -0.05, 0.02, 0.8, 0.1, -0.1, 0.05, 1.1, 0.03, -0.02, 0.05}));
}

// Bidirectional supervision: a term's gradient with respect to the other branch's renders it
// declares (LossTerm::TargetInputs), against central differences. The mutual depth holds max Z
// constant, so its argmax pixel is skipped as above.
void ExpectTargetGradientMatchesNumeric(const LossTerm& term) {
  SCOPED_TRACE(term.Name());
  Fixture f(3);
  TargetGradientsD grad;
  const double scale = 1.3;
  term.EvaluateTargetGradient(f.in, f.targets, scale, &grad);
  ASSERT_FALSE(term.TargetInputs().empty());
  for (OtherBranchTarget which : term.TargetInputs()) {
    const bool tran = which == OtherBranchTarget::kTransmitted;
    ImageD& x = tran ? f.transmitted : f.other_depth;
    const ImageD& g = tran ? grad.transmitted : grad.other_depth;
    ASSERT_EQ(g.size(), x.size());
    const size_t argmax = std::max_element(x.data(), x.data() + x.size()) - x.data();
    int nonzero = 0;
    for (size_t i = 0; i < x.size(); ++i) {
      if (!tran && i == argmax) continue;
      const double keep = x.data()[i], h = 1e-6;
      x.data()[i] = keep + h;
      const double vp = term.Evaluate(f.in, f.targets, 1.0, nullptr);
      x.data()[i] = keep - h;
      const double vm = term.Evaluate(f.in, f.targets, 1.0, nullptr);
      x.data()[i] = keep;
      const double numeric = scale * (vp - vm) / (2 * h);
      EXPECT_NEAR(g.data()[i], numeric, 1e-6 + 1e-5 * std::abs(numeric))
          << (tran ? "transmitted" : "other depth") << "[" << i << "]";
      nonzero += std::abs(numeric) > 1e-9;
    }
    EXPECT_GT(nonzero, 0);
  }
}

TEST(LossGradientTest, TargetGradientsMatchNumericDifferentiation) {
  ExpectTargetGradientMatchesNumeric(L1Loss(Buffer::kColor, TargetKind::kTransmitted));
  ExpectTargetGradientMatchesNumeric(DssimLoss(Buffer::kColor, TargetKind::kTransmitted));
  ExpectTargetGradientMatchesNumeric(RenderLoss(Buffer::kColor, TargetKind::kTransmitted, 0.8));
  ExpectTargetGradientMatchesNumeric(MutualRenderLoss(0.3, 0.7, 0.8));
  ExpectTargetGradientMatchesNumeric(MutualDepthLoss(false));
  ExpectTargetGradientMatchesNumeric(MutualDepthLoss(true));
  // Constants stay constants: the photo, and the TV's guide even when it is the transmitted image.
  EXPECT_TRUE(L1Loss(Buffer::kColor, TargetKind::kImage).TargetInputs().empty());
  EXPECT_TRUE(EdgeAwareTvLoss(Buffer::kDepth, TargetKind::kTransmitted).TargetInputs().empty());
  // Every registered term, as configured against the transmitted image where it can be: what it
  // declares matches.
  for (const std::string& name : LossRegistry::Get().Names()) {
    Status status;
    for (const char* config : {"{}", R"({"target": "transmitted"})"}) {
      auto term = LossRegistry::Get().Create(name, nlohmann::json::parse(config), &status);
      if (term != nullptr && !term->TargetInputs().empty())
        ExpectTargetGradientMatchesNumeric(*term);
    }
  }
}

// The colour transform's own parameters: analytic against central differences, with and without
// a mask, through the full render loss (L1 + D-SSIM).
TEST(LossGradientTest, ExposureParametersMatchNumericDifferentiation) {
  for (bool masked : {true, false}) {
    SCOPED_TRACE(masked ? "masked" : "unmasked");
    Fixture f(7);
    if (!masked) f.targets.mask = nullptr;
    const ColorTransform p0 = {1.2,  0.1,  -0.05, 0.02, 0.85,  0.1,
                               -0.1, 0.05, 1.1,   0.03, -0.02, 0.05};
    ExposureCompensatedLoss term(
        std::make_unique<RenderLoss>(Buffer::kColor, TargetKind::kImage, 0.8), p0);
    RenderGradientsD grad;
    const double scale = 0.6;
    term.Evaluate(f.in, f.targets, scale, &grad);
    const ColorTransform analytic = term.parameter_gradient();
    for (int k = 0; k < kColorTransformSize; ++k) {
      const double h = 1e-6;
      ColorTransform p = p0;
      p[k] += h;
      term.set_transform(p);
      const double vp = term.Evaluate(f.in, f.targets, 1.0, nullptr);
      p[k] -= 2 * h;
      term.set_transform(p);
      const double vm = term.Evaluate(f.in, f.targets, 1.0, nullptr);
      const double numeric = scale * (vp - vm) / (2 * h);
      EXPECT_NEAR(analytic[k], numeric, 1e-7 + 1e-5 * std::abs(numeric)) << "parameter " << k;
      EXPECT_GT(std::abs(numeric), 1e-6) << "parameter " << k << " should matter";
    }
    term.set_transform(p0);
  }
}

TEST(LossValueTest, ExposureTransformUndoesAKnownGainAndLeavesTheBackgroundAlone) {
  Fixture f(11);
  // The photo is the render with gains (0.5, 0.7, 1.4) and an offset inside the mask; outside it,
  // the render as it is. The matching transform gives zero loss, identity does not.
  const ImageD& color = f.buffers[static_cast<int>(Buffer::kColor)];
  ImageD photo(color.width(), color.height(), 3);
  const double gain[3] = {0.5, 0.7, 1.4}, offset[3] = {0.02, -0.01, 0.03};
  for (int c = 0; c < 3; ++c) {
    for (size_t i = 0; i < photo.plane_size(); ++i) {
      const double m = f.mask.plane(0)[i];
      const double x = color.plane(c)[i];
      photo.plane(c)[i] = m * (gain[c] * x + offset[c]) + (1 - m) * x;
    }
  }
  f.targets.image = &photo;
  ExposureCompensatedLoss term(std::make_unique<L1Loss>(Buffer::kColor, TargetKind::kImage));
  EXPECT_GT(term.Evaluate(f.in, f.targets, 1.0, nullptr), 0.01);
  term.set_transform({0.5, 0, 0, 0, 0.7, 0, 0, 0, 1.4, 0.02, -0.01, 0.03});
  EXPECT_LT(term.Evaluate(f.in, f.targets, 1.0, nullptr), 1e-12);
  ExposureMode mode;
  EXPECT_TRUE(ParseExposureMode("diag", &mode).ok());
  EXPECT_EQ(mode, ExposureMode::kDiagonal);
  EXPECT_FALSE(ParseExposureMode("full", &mode).ok());
  EXPECT_TRUE(ColorTransformParameterIsFree(ExposureMode::kDiagonal, 4));
  EXPECT_FALSE(ColorTransformParameterIsFree(ExposureMode::kDiagonal, 1));
}

TEST(LossGradientTest, EveryRegisteredTermPassesTheHarness) {
  for (const std::string& name : LossRegistry::Get().Names()) {
    Status s;
    // Random depths and normals lie on no plane: the patch term would skip every patch; its
    // random patches would fall on both sides of the outlier threshold.
    const nlohmann::json config =
        name == "multiview_ncc" ? nlohmann::json{{"max_plane_offset_px", 0}, {"max_pair_loss", 2}}
                                : nlohmann::json::object();
    auto term = LossRegistry::Get().Create(name, config, &s);
    ASSERT_TRUE(s.ok()) << s.message();
    ExpectGradientMatchesNumeric(*term, 3);
  }
}

// The interface really is Ceres-shaped: a term wrapped as a ceres::CostFunction (one residual, the
// value; one parameter block, the input buffer) passes ceres::GradientChecker.
class LossTermCostFunction : public ceres::CostFunction {
 public:
  LossTermCostFunction(const LossTerm* term, Fixture* fixture, Buffer buffer)
      : term_(term), f_(fixture), buffer_(buffer) {
    set_num_residuals(1);
    mutable_parameter_block_sizes()->push_back(
        static_cast<int32_t>(f_->buffers[static_cast<int>(buffer)].size()));
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    ImageD& x = f_->buffers[static_cast<int>(buffer_)];
    std::copy(parameters[0], parameters[0] + x.size(), x.data());
    RenderGradientsD grad;
    residuals[0] = term_->Evaluate(f_->in, f_->targets, 1.0, jacobians ? &grad : nullptr);
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      const ImageD& g = grad.Get(buffer_);
      for (size_t i = 0; i < x.size(); ++i) jacobians[0][i] = g.empty() ? 0.0 : g.data()[i];
    }
    return true;
  }

 private:
  const LossTerm* term_;
  Fixture* f_;
  Buffer buffer_;
};

TEST(LossGradientTest, CeresGradientCheckerAcceptsTheTerms) {
  for (int which = 0; which < 2; ++which) {
    Fixture f(5);
    DssimLoss dssim;
    NormalConsistencyLoss normal;
    const LossTerm* term = which == 0 ? static_cast<const LossTerm*>(&dssim) : &normal;
    const Buffer buffer = which == 0 ? Buffer::kColor : Buffer::kDepth;
    LossTermCostFunction cost(term, &f, buffer);
    std::vector<double> x(
        f.buffers[static_cast<int>(buffer)].data(),
        f.buffers[static_cast<int>(buffer)].data() + f.buffers[static_cast<int>(buffer)].size());
    const double* blocks[] = {x.data()};
    ceres::NumericDiffOptions options;
    // GradientChecker uses Ridders' method; its default first step (1% of the value) is too coarse
    // for the rough random depth maps of this fixture.
    options.ridders_relative_initial_step_size = 1e-4;
    ceres::GradientChecker checker(
        &cost, static_cast<const std::vector<const ceres::Manifold*>*>(nullptr), options);
    ceres::GradientChecker::ProbeResults results;
    EXPECT_TRUE(checker.Probe(blocks, 1e-5, &results)) << term->Name() << ": " << results.error_log;
  }
}

TEST(LossValueTest, HandComputedCases) {
  Fixture f(7);
  // L1 of a constant offset.
  ImageD shifted = f.image;
  for (size_t i = 0; i < shifted.size(); ++i) shifted.data()[i] += 0.25;
  f.in.Set(Buffer::kColor, &shifted);
  EXPECT_NEAR(L1Loss().Evaluate(f.in, f.targets, 1, nullptr), 0.25, 1e-12);
  // D-SSIM of identical images is 0, and SSIM matches the evaluation metric.
  f.in.Set(Buffer::kColor, &f.image);
  EXPECT_NEAR(DssimLoss().Evaluate(f.in, f.targets, 1, nullptr), 0.0, 1e-12);
  f.in.Set(Buffer::kColor, &f.buffers[0]);
  EXPECT_NEAR(1.0 - DssimLoss().Evaluate(f.in, f.targets, 1, nullptr),
              Ssim(f.buffers[0].Cast<float>(), f.image.Cast<float>()), 1e-5);
  // TV of a horizontal ramp with a flat guide: only horizontal steps, each a^2.
  ImageD ramp(14, 11, 1), flat(14, 11, 3, 0.5);
  for (int y = 0; y < 11; ++y) {
    for (int x = 0; x < 14; ++x) ramp.at(0, y, x) = 0.3 * x;
  }
  f.in.Set(Buffer::kDepth, &ramp);
  f.targets.image = &flat;
  EXPECT_NEAR(EdgeAwareTvLoss(Buffer::kDepth).Evaluate(f.in, f.targets, 1, nullptr), 0.09, 1e-12);
  // On geometry: the same ramp with sky (alpha 0, depth 0) in its right half. The plain TV sees
  // the step down to the sky; on geometry only the ramp's own steps count (5 of 13 columns of
  // pairs), and the sky pixels get no gradient.
  ImageD with_sky = ramp, alpha(14, 11, 1, 1.0);
  for (int y = 0; y < 11; ++y) {
    for (int x = 6; x < 14; ++x) with_sky.at(0, y, x) = alpha.at(0, y, x) = 0;
  }
  f.in.Set(Buffer::kDepth, &with_sky);
  f.in.Set(Buffer::kAlpha, &alpha);
  const EdgeAwareTvLoss on_geometry(Buffer::kDepth, TargetKind::kImage, true);
  EXPECT_GT(EdgeAwareTvLoss(Buffer::kDepth).Evaluate(f.in, f.targets, 1, nullptr), 0.2);
  RenderGradientsD tv_grad;
  EXPECT_NEAR(on_geometry.Evaluate(f.in, f.targets, 1, &tv_grad), 0.09 * 5 / 13, 1e-12);
  const ImageD& g_depth = tv_grad.Get(Buffer::kDepth);
  for (int y = 0; y < 11; ++y) {
    EXPECT_NE(g_depth.at(0, y, 5), 0.0);
    for (int x = 6; x < 14; ++x) EXPECT_EQ(g_depth.at(0, y, x), 0.0);
  }
  // Disparity TV: the plain TV of s^2 / D (written out); zero on a plane seen in perspective
  // (whose plain depth TV is not); close to the plain TV of D where D ~ s; pixels without depth
  // drop out.
  ImageD ramp_far(14, 11, 1), disparity(14, 11, 1), plane(14, 11, 1);
  for (int y = 0; y < 11; ++y) {
    for (int x = 0; x < 14; ++x) {
      ramp_far.at(0, y, x) = 3 + ramp.at(0, y, x);
      disparity.at(0, y, x) = 4 / ramp_far.at(0, y, x);
      plane.at(0, y, x) = 1 / (0.05 + 0.01 * x + 0.02 * y);  // a plane's depth: 1 / affine
    }
  }
  const EdgeAwareTvLoss disparity_tv(Buffer::kDepth, TargetKind::kImage, false, 2.0);
  f.in.Set(Buffer::kDepth, &disparity);
  const double plain_of_disparity =
      EdgeAwareTvLoss(Buffer::kDepth).Evaluate(f.in, f.targets, 1, nullptr);
  f.in.Set(Buffer::kDepth, &ramp_far);
  EXPECT_NEAR(disparity_tv.Evaluate(f.in, f.targets, 1, nullptr), plain_of_disparity,
              1e-12 * plain_of_disparity);
  f.in.Set(Buffer::kDepth, &plane);
  EXPECT_GT(EdgeAwareTvLoss(Buffer::kDepth).Evaluate(f.in, f.targets, 1, nullptr), 1.0);
  RenderGradientsD plane_grad;
  disparity_tv.Evaluate(f.in, f.targets, 1, &plane_grad);
  for (int y = 1; y < 10; ++y)  // interior: the second differences of an affine map vanish
    for (int x = 1; x < 13; ++x) EXPECT_NEAR(plane_grad.Get(Buffer::kDepth).at(0, y, x), 0, 1e-9);
  ImageD ramp_at_30 = ramp;  // 30 .. 33.9: within 7% of its middle
  for (size_t i = 0; i < ramp.size(); ++i) ramp_at_30.data()[i] += 30;
  f.in.Set(Buffer::kDepth, &ramp_at_30);
  EXPECT_NEAR(EdgeAwareTvLoss(Buffer::kDepth, TargetKind::kImage, false, 31.95)
                  .Evaluate(f.in, f.targets, 1, nullptr),
              0.09, 0.01);
  ImageD with_hole = ramp_far;
  for (int y = 0; y < 11; ++y) with_hole.at(0, y, 13) = 0;  // the last column has no depth
  f.in.Set(Buffer::kDepth, &with_hole);
  RenderGradientsD hole_grad;
  double without_last = 0;  // the mean over all 13 columns of pairs, of the 12 that remain
  for (int x = 0; x < 12; ++x)
    without_last += std::pow(4 / (3 + 0.3 * (x + 1)) - 4 / (3 + 0.3 * x), 2) / 13;
  EXPECT_NEAR(disparity_tv.Evaluate(f.in, f.targets, 1, &hole_grad), without_last, 1e-12);
  for (int y = 0; y < 11; ++y) EXPECT_EQ(hole_grad.Get(Buffer::kDepth).at(0, y, 13), 0.0);
  // Mutual depth of proportional depths is 0 (max normalisation).
  ImageD twice = ramp;
  for (size_t i = 0; i < twice.size(); ++i) twice.data()[i] = 2 * ramp.data()[i] + 2;
  ImageD base = twice;
  for (size_t i = 0; i < base.size(); ++i) base.data()[i] = 0.5 * twice.data()[i];
  f.in.Set(Buffer::kDepth, &base);
  f.targets.other_depth = &twice;
  EXPECT_NEAR(MutualDepthLoss().Evaluate(f.in, f.targets, 1, nullptr), 0.0, 1e-15);
}

// The silhouette term: hand-computed cross-entropy, nothing without a mask, and no push on a pixel
// already clamped at full or no opacity.
TEST(LossValueTest, MaskLossIsTheCrossEntropyOfAlphaAgainstTheMask) {
  Fixture f(3);
  ImageD alpha(2, 1, 1), mask(2, 1, 1);
  alpha.data()[0] = 0.8;  // foreground, mostly covered
  alpha.data()[1] = 0.3;  // background with a disk in front
  mask.data()[0] = 1;
  mask.data()[1] = 0;
  f.in.Set(Buffer::kAlpha, &alpha);
  f.targets.mask = &mask;
  RenderGradientsD g;
  EXPECT_NEAR(MaskLoss().Evaluate(f.in, f.targets, 2.0, &g), -(std::log(0.8) + std::log(0.7)) / 2,
              1e-12);
  EXPECT_NEAR(g.Get(Buffer::kAlpha).data()[0], 2.0 / 2 * (0.8 - 1) / (0.8 * 0.2), 1e-12);
  EXPECT_NEAR(g.Get(Buffer::kAlpha).data()[1], 2.0 / 2 * 0.3 / (0.3 * 0.7), 1e-12);
  // An empty background pixel and an opaque foreground one: value ~0, no gradient.
  alpha.data()[0] = 1.0;
  alpha.data()[1] = 0.0;
  RenderGradientsD clamped;
  EXPECT_NEAR(MaskLoss().Evaluate(f.in, f.targets, 1.0, &clamped), -std::log(1 - MaskLoss::kEps),
              1e-12);
  EXPECT_EQ(clamped.Get(Buffer::kAlpha).data()[0], 0.0);
  EXPECT_EQ(clamped.Get(Buffer::kAlpha).data()[1], 0.0);
  f.targets.mask = nullptr;
  EXPECT_FALSE(MaskLoss().Check(RenderBuffers(), Targets()).ok());  // no alpha to read
  EXPECT_EQ(MaskLoss().Evaluate(f.in, f.targets, 1.0, nullptr), 0.0);
}

// The fused SSIM kernel behind DssimLoss: its value against the direct window sum, its gradient
// against central differences (borders included), float against double, and the same bits with
// one thread as with several. 300 x 230 and 130 x 129 take the threaded path (from 16,384 pixels:
// a 128 px view), 7 x 4 is smaller than the window.
TEST(DssimPlaneTest, MatchesTheDirectWindowAndCentralDifferencesOnAnyThreadCount) {
  for (const auto& [w, h] :
       std::vector<std::pair<int, int>>{{300, 230}, {130, 129}, {7, 4}, {23, 17}}) {
    SCOPED_TRACE(std::to_string(w) + " x " + std::to_string(h));
    Rng rng(w * 31 + h);
    const size_t n = static_cast<size_t>(w) * h;
    std::vector<double> x(n), y(n);
    for (size_t i = 0; i < n; ++i) {
      y[i] = rng.Uniform();
      x[i] = std::clamp(y[i] + rng.Uniform(-0.3, 0.3), 0.0, 1.0);
    }
    const double scale = -0.7;
    std::vector<double> grad(n, 0.0);
    const double value = SsimPlaneSum(x.data(), y.data(), w, h, scale, grad.data());
    EXPECT_NEAR(value, testing::DirectSsimSum(x.data(), y.data(), w, h), 1e-12 * n);
    std::vector<size_t> probes = {0, static_cast<size_t>(w - 1), n - 1, n - w, n / 2 + w / 3};
    for (int k = 0; k < 25; ++k) probes.push_back(rng.UniformInt(n));
    for (size_t i : probes) {
      // A sum over up to 69,000 pixels: a larger step than usual keeps its cancellation error
      // (~1e-16 x sum / step) far below the tolerance.
      const double keep = x[i], step = 1e-4;
      x[i] = keep + step;
      const double vp = SsimPlaneSum(x.data(), y.data(), w, h, 1.0, nullptr);
      x[i] = keep - step;
      const double vm = SsimPlaneSum(x.data(), y.data(), w, h, 1.0, nullptr);
      x[i] = keep;
      const double numeric = scale * (vp - vm) / (2 * step);
      EXPECT_NEAR(grad[i], numeric, 1e-7 + 1e-5 * std::abs(numeric)) << "pixel " << i;
    }
    // Float, as training runs it.
    const std::vector<float> xf(x.begin(), x.end()), yf(y.begin(), y.end());
    std::vector<float> gf(n, 0.0f), gf1(n, 0.0f);
    const double vf =
        SsimPlaneSum(xf.data(), yf.data(), w, h, static_cast<float>(scale), gf.data());
    EXPECT_NEAR(vf, value, 1e-5 * n);
    double max_grad = 0, max_diff = 0;
    for (size_t i = 0; i < n; ++i) {
      max_grad = std::max(max_grad, std::abs(grad[i]));
      max_diff = std::max(max_diff, std::abs(gf[i] - grad[i]));
    }
    EXPECT_LT(max_diff, 1e-4 * max_grad);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const double vf1 =
        SsimPlaneSum(xf.data(), yf.data(), w, h, static_cast<float>(scale), gf1.data());
    omp_set_num_threads(threads);
    EXPECT_EQ(vf1, vf);
    EXPECT_EQ(gf1, gf);
  }
}

// The edge-aware TV kernel: its sums against the definition written out directly, float against
// double, and the same bits with one thread as with several (300 x 230 takes the threaded path),
// with and without per-pixel weights gamma. Its double gradient is checked here and by
// EveryTermMatchesNumericDifferentiation.
TEST(EdgeAwareTvPlaneTest, MatchesTheDefinitionOnAnyThreadCount) {
  for (const auto& [w, h, channels, weighted] :
       std::vector<std::tuple<int, int, int, bool>>{{300, 230, 3, false},
                                                    {300, 230, 1, false},
                                                    {17, 2, 3, false},
                                                    {300, 230, 1, true},
                                                    {17, 2, 3, true}}) {
    SCOPED_TRACE(std::to_string(w) + " x " + std::to_string(h) + " x " + std::to_string(channels) +
                 (weighted ? " weighted" : ""));
    Rng rng(w + h + channels);
    const size_t n = static_cast<size_t>(w) * h;
    std::vector<double> P(channels * n), I(3 * n), gamma(n, 1.0);
    for (double& v : P) v = rng.Uniform(-1, 2);
    for (double& v : I) v = rng.Uniform();
    // Zero, one and values between, as alpha is over sky, surface and edges.
    if (weighted)
      for (double& v : gamma) v = std::clamp(rng.Uniform(-0.3, 1.3), 0.0, 1.0);
    const double* G = weighted ? gamma.data() : nullptr;
    const std::vector<float> gammaf(gamma.begin(), gamma.end());
    const float* Gf = weighted ? gammaf.data() : nullptr;
    double direct_v = 0, direct_h = 0;
    for (int c = 0; c < channels; ++c) {
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          auto at = [&](const std::vector<double>& im, int ch, int yy, int xx) {
            return im[ch * n + static_cast<size_t>(yy) * w + xx];
          };
          auto weight = [&](int y1, int x1) {
            double d = 0;
            for (int k = 0; k < 3; ++k) d += std::abs(at(I, k, y1, x1) - at(I, k, y, x));
            return std::exp(-d / 3) * gamma[static_cast<size_t>(y1) * w + x1] *
                   gamma[static_cast<size_t>(y) * w + x];
          };
          if (y + 1 < h)
            direct_v += weight(y + 1, x) * std::pow(at(P, c, y + 1, x) - at(P, c, y, x), 2);
          if (x + 1 < w)
            direct_h += weight(y, x + 1) * std::pow(at(P, c, y, x + 1) - at(P, c, y, x), 2);
        }
      }
    }
    double v = 0, hz = 0;
    std::vector<double> g(P.size(), 0.0);
    EdgeAwareTvSums(P.data(), channels, I.data(), 3, G, w, h, 0.3, 0.7, g.data(), &v, &hz);
    EXPECT_NEAR(v, direct_v, 1e-10 * direct_v);
    EXPECT_NEAR(hz, direct_h, 1e-10 * direct_h);
    // The gradient at corners, edges and random pixels, against central differences.
    std::vector<size_t> probes = {0, static_cast<size_t>(w - 1), n - 1, n - w, n + w / 2};
    for (int k = 0; k < 12; ++k) probes.push_back(rng.UniformInt(P.size()));
    for (size_t i : probes) {
      if (i >= P.size()) continue;
      const double keep = P[i], step = 1e-4;
      double vp, hp, vm, hm;
      P[i] = keep + step;
      EdgeAwareTvSums(P.data(), channels, I.data(), 3, G, w, h, 0.0, 0.0, nullptr, &vp, &hp);
      P[i] = keep - step;
      EdgeAwareTvSums(P.data(), channels, I.data(), 3, G, w, h, 0.0, 0.0, nullptr, &vm, &hm);
      P[i] = keep;
      const double numeric = (0.3 * (vp - vm) + 0.7 * (hp - hm)) / (2 * step);
      EXPECT_NEAR(g[i], numeric, 1e-7 + 1e-6 * std::abs(numeric)) << "element " << i;
    }
    const std::vector<float> Pf(P.begin(), P.end()), If(I.begin(), I.end());
    std::vector<float> gf(P.size(), 0.0f), gf1(P.size(), 0.0f);
    double vf = 0, hf = 0, vf1 = 0, hf1 = 0;
    EdgeAwareTvSums(Pf.data(), channels, If.data(), 3, Gf, w, h, 0.3f, 0.7f, gf.data(), &vf, &hf);
    EXPECT_NEAR(vf, v, 1e-5 * v);
    EXPECT_NEAR(hf, hz, 1e-5 * hz);
    double max_g = 0, max_diff = 0;
    for (size_t i = 0; i < g.size(); ++i) {
      max_g = std::max(max_g, std::abs(g[i]));
      max_diff = std::max(max_diff, std::abs(gf[i] - g[i]));
    }
    EXPECT_LT(max_diff, 1e-5 * max_g);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    EdgeAwareTvSums(Pf.data(), channels, If.data(), 3, Gf, w, h, 0.3f, 0.7f, gf1.data(), &vf1,
                    &hf1);
    omp_set_num_threads(threads);
    EXPECT_EQ(vf1, vf);
    EXPECT_EQ(hf1, hf);
    EXPECT_EQ(gf1, gf);
  }
}

// The depth-normal consistency's pixel loop as it was written before its vectorised kernel
// (NormalConsistencySum): Eigen 3-vectors, one pixel at a time, rows in three phases. The kernel
// must give its values and gradients to the bit.
double ScalarNormalConsistency(const NormalConsistencyPlanes<float>& p) {
  using V = Eigen::Vector3f;
  const int w = p.width, h = p.height;
  auto at = [&](const float* plane, int x, int y) { return plane[static_cast<size_t>(y) * w + x]; };
  auto ray = [&](int x, int y) {
    return V(at(p.ray[0], x, y), at(p.ray[1], x, y), at(p.ray[2], x, y));
  };
  const V C(p.center[0], p.center[1], p.center[2]);
  auto P = [&](int x, int y) -> V { return C + at(p.depth, x, y) * ray(x, y); };
  std::vector<double> row_total(h, 0.0);
  for (int phase = 0; phase < 3; ++phase) {
    for (int y = phase; y < h; y += 3) {
      double total = 0;
      for (int x = 0; x < w; ++x) {
        const size_t i = static_cast<size_t>(y) * w + x;
        const float gamma = p.mask != nullptr ? p.mask[i] : 1.0f;
        const V n_rend(p.normal[0][i], p.normal[1][i], p.normal[2][i]);
        const bool interior = x > 0 && y > 0 && x + 1 < w && y + 1 < h;
        // The ends of each difference: central, or the centre and its closer neighbour.
        int x_hi = x + 1, x_lo = x - 1, y_hi = y + 1, y_lo = y - 1;
        if (p.one_sided && interior) {
          // An axis with a step (one jump over kNormalStepRatio times the other) goes one-sided.
          const float d = at(p.depth, x, y), k = kNormalStepRatio;
          const float jr = std::abs(at(p.depth, x + 1, y) - d);
          const float jl = std::abs(d - at(p.depth, x - 1, y));
          const float jd = std::abs(at(p.depth, x, y + 1) - d);
          const float ju = std::abs(d - at(p.depth, x, y - 1));
          if (jr > k * jl || jl > k * jr) (jr < jl ? x_lo : x_hi) = x;
          if (jd > k * ju || ju > k * jd) (jd < ju ? y_lo : y_hi) = y;
        }
        V dy = V::Zero(), dx = V::Zero(), c = V::Zero();
        float len = 0;
        if (interior) {
          dy = P(x, y_hi) - P(x, y_lo);
          dx = P(x_hi, y) - P(x_lo, y);
          c = dy.cross(dx);
          len = c.norm();
        }
        const bool defined = interior && len > 0.0f;
        const V n_surf = defined ? V(c / len) : V::Zero();
        const float a = p.alpha[i];
        const float res = 1 - n_rend.dot(n_surf) * a;
        const bool robust = p.robust_scale > 0.0f;
        const float ratio = robust ? p.robust_scale / (res + p.robust_scale) : 1.0f;
        total += robust ? gamma * (res * ratio) : gamma * res;
        if (p.d_depth == nullptr || gamma == 0.0f) continue;
        const float s = robust ? p.gain * gamma * a * (ratio * ratio) : p.gain * gamma * a;
        for (int k = 0; k < 3; ++k) p.d_normal[k][i] += s * n_surf[k];
        if (!defined) continue;
        const V dn = s * n_rend;
        const V dc = (dn - n_surf * n_surf.dot(dn)) / len;
        const V d_dy = dx.cross(dc);
        const V d_dx = dc.cross(dy);
        if (!p.one_sided) {
          p.d_depth[i + w] += d_dy.dot(ray(x, y + 1));
          p.d_depth[i - w] -= d_dy.dot(ray(x, y - 1));
          p.d_depth[i + 1] += d_dx.dot(ray(x + 1, y));
          p.d_depth[i - 1] -= d_dx.dot(ray(x - 1, y));
          continue;
        }
        // One-sided: the neighbours' shares, then the centre's (its x share before its y share;
        // zero along an axis that stayed central).
        if (y_hi != y) p.d_depth[i + w] += d_dy.dot(ray(x, y + 1));
        if (y_lo != y) p.d_depth[i - w] -= d_dy.dot(ray(x, y - 1));
        if (x_hi != x) p.d_depth[i + 1] += d_dx.dot(ray(x + 1, y));
        const float cx_share = d_dx.dot(ray(x, y)), cy_share = d_dy.dot(ray(x, y));
        const float sx = x_hi == x ? cx_share : (x_lo == x ? -cx_share : 0.0f);
        const float sy = y_hi == y ? cy_share : (y_lo == y ? -cy_share : 0.0f);
        p.d_depth[i] += sx + sy;
        if (x_lo != x) p.d_depth[i - 1] -= d_dx.dot(ray(x - 1, y));
      }
      row_total[y] = total;
    }
  }
  double total = 0;
  for (int y = 0; y < h; ++y) total += row_total[y];
  return total;
}

TEST(NormalConsistencyPlaneTest, MatchesTheScalarLoopToTheBitOnAnyThreadCount) {
  for (const auto& [w, h, masked, robust, one_sided] :
       std::vector<std::tuple<int, int, bool, float, bool>>{{256, 256, true, 0.0f, false},
                                                            {256, 256, false, 0.0f, false},
                                                            {256, 256, true, 0.1f, false},
                                                            {256, 256, true, 0.0f, true},
                                                            {37, 5, true, 0.0f, false},
                                                            {37, 5, false, 0.2f, true},
                                                            {19, 1, false, 0.0f, false},
                                                            {1, 7, true, 0.05f, false},
                                                            {2, 2, false, 0.0f, true},
                                                            {300, 41, true, 0.0f, false},
                                                            {300, 41, false, 0.3f, true}}) {
    SCOPED_TRACE(std::to_string(w) + " x " + std::to_string(h) + (masked ? " masked" : "") +
                 " robust " + std::to_string(robust) + (one_sided ? " one-sided" : ""));
    Rng rng(7 * w + h);
    const size_t n = static_cast<size_t>(w) * h;
    std::vector<float> depth(n), normal(3 * n), alpha(n), mask(n), rays(3 * n);
    for (size_t i = 0; i < n; ++i) {
      // A smooth surface with steps, flat patches (degenerate normals: equal depths along a
      // ray fan still differ, so also exact zeros) and holes.
      const int x = static_cast<int>(i % w), y = static_cast<int>(i / w);
      const double u = rng.Uniform();
      depth[i] = u < 0.05 ? 0.0f
                          : static_cast<float>(2.0 + 0.3 * std::sin(0.1 * x) + 0.01 * y +
                                               (u > 0.9 ? 0.5 : 0.0));
      alpha[i] = static_cast<float>(std::clamp(rng.Uniform(-0.2, 1.2), 0.0, 1.0));
      mask[i] = static_cast<float>(std::clamp(rng.Uniform(-0.5, 1.5), 0.0, 1.0));
      for (int k = 0; k < 3; ++k) normal[k * n + i] = static_cast<float>(rng.Uniform(-1, 1));
      rays[i] = static_cast<float>((x + 0.5 - 0.5 * w) / (0.9 * w));
      rays[n + i] = static_cast<float>((y + 0.5 - 0.5 * h) / (0.9 * w));
      rays[2 * n + i] = 1.0f;
    }
    for (int x = 0; x < w; ++x) depth[static_cast<size_t>(h / 2) * w + x] = 0.0f;  // a zero row
    NormalConsistencyPlanes<float> p;
    p.width = w;
    p.height = h;
    p.depth = depth.data();
    p.alpha = alpha.data();
    p.mask = masked ? mask.data() : nullptr;
    for (int k = 0; k < 3; ++k) {
      p.normal[k] = normal.data() + k * n;
      p.ray[k] = rays.data() + k * n;
    }
    p.center[0] = 0.1f;
    p.center[1] = -0.2f;
    p.center[2] = -3.0f;
    p.gain = -0.37f;
    p.robust_scale = robust;
    p.one_sided = one_sided;
    auto run = [&](bool reference, std::vector<float>* dn, std::vector<float>* dd) {
      // Start from non-zero gradients, as other terms have added theirs.
      dn->assign(3 * n, 0.25f);
      dd->assign(n, -0.5f);
      NormalConsistencyPlanes<float> q = p;
      for (int k = 0; k < 3; ++k) q.d_normal[k] = dn->data() + k * n;
      q.d_depth = dd->data();
      return reference ? ScalarNormalConsistency(q) : NormalConsistencySum(q);
    };
    std::vector<float> dn_ref, dd_ref, dn, dd, dn1, dd1;
    const double ref = run(true, &dn_ref, &dd_ref);
    EXPECT_EQ(run(false, &dn, &dd), ref);
    EXPECT_EQ(dn, dn_ref);
    EXPECT_EQ(dd, dd_ref);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    EXPECT_EQ(run(false, &dn1, &dd1), ref);
    omp_set_num_threads(threads);
    EXPECT_EQ(dn1, dn_ref);
    EXPECT_EQ(dd1, dd_ref);
    // Without gradients: the same value.
    NormalConsistencyPlanes<float> value_only = p;
    EXPECT_EQ(NormalConsistencySum(value_only), ref);
  }
}

// The depth-normal consistency of a depth and rendered normals at alpha 1, over the mask.
double NormalConsistencyAtFullAlpha(const Camera& cam, const ImageD& depth, const ImageD& normals,
                                    const ImageD& mask, const NormalConsistencyOptions& options) {
  const ImageD alpha(depth.width(), depth.height(), 1, 1.0);
  RenderBuffersD in;
  in.camera = &cam;
  in.Set(Buffer::kDepth, &depth);
  in.Set(Buffer::kNormal, &normals);
  in.Set(Buffer::kAlpha, &alpha);
  TargetsD t;
  t.mask = &mask;
  return NormalConsistencyLoss(options).Evaluate(in, t, 1, nullptr);
}

TEST(LossValueTest, DepthOfATiltedPlaneGivesItsNormal) {
  const Camera cam =
      LookAtCamera({0.5, -3, 1}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 20, 16, 24, 24);
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -1, 0.4).normalized();
  ImageD depth(20, 16, 1);
  for (int y = 0; y < 16; ++y) {
    for (int x = 0; x < 20; ++x) {
      const Eigen::Vector3d ray = cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5);
      depth.at(0, y, x) = -n.dot(cam.Center()) / n.dot(ray);
    }
  }
  const ImageD normals = DepthToNormal(depth, cam);
  const Eigen::Vector3d facing = n.dot(cam.Center()) > 0 ? n : Eigen::Vector3d(-n);
  for (int y = 1; y < 15; ++y) {
    for (int x = 1; x < 19; ++x) {
      const Eigen::Vector3d got(normals.at(0, y, x), normals.at(1, y, x), normals.at(2, y, x));
      EXPECT_NEAR((got - facing).norm(), 0, 1e-9) << x << "," << y;
    }
  }
  EXPECT_EQ(normals.at(0, 0, 0), 0.0);  // border
  // And the consistency loss of matching normals with alpha 1 is 0 inside the border.
  ImageD mask(20, 16, 1, 0.0);
  for (int y = 1; y < 15; ++y) {
    for (int x = 1; x < 19; ++x) mask.at(0, y, x) = 1.0;
  }
  EXPECT_NEAR(NormalConsistencyAtFullAlpha(cam, depth, normals, mask, {}), 0.0, 1e-12);
}

// Two parallel tilted planes side by side (a step, as where a tooth stands in front of a groove),
// and the planes' own normals rendered: central differences straddle the step and give both of
// its columns a slanted normal; one-sided ones take each column's own plane; on the planes
// themselves (no step) both agree.
TEST(LossValueTest, OneSidedDifferencesDoNotSlantTheNormalsAtAStep) {
  const int w = 20, h = 16;
  const Camera cam = LookAtCamera({0.5, -3, 1}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), w, h, 24, 24);
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -1, 0.4).normalized();
  const Eigen::Vector3d facing = n.dot(cam.Center()) > 0 ? n : Eigen::Vector3d(-n);
  ImageD depth(w, h, 1), normals(w, h, 3), mask(w, h, 1, 1.0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector3d ray = cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5);
      const double offset = x >= 10 ? 0.6 : 0.0;  // the right half lies further along n
      depth.at(0, y, x) = (offset - n.dot(cam.Center())) / n.dot(ray);
      for (int k = 0; k < 3; ++k) normals.at(k, y, x) = facing[k];
    }
  }
  NormalConsistencyOptions one_sided;
  one_sided.one_sided = true;
  // Per-column loss: only the two columns beside the step differ.
  for (int step_column : {9, 10, 4}) {
    mask.Fill(0.0);
    for (int y = 1; y + 1 < h; ++y) mask.at(0, y, step_column) = 1.0;
    const double central = NormalConsistencyAtFullAlpha(cam, depth, normals, mask, {});
    const double sided = NormalConsistencyAtFullAlpha(cam, depth, normals, mask, one_sided);
    SCOPED_TRACE("column " + std::to_string(step_column));
    EXPECT_NEAR(sided, 0.0, 1e-12);
    if (step_column == 4) {
      EXPECT_NEAR(central, 0.0, 1e-12);
    } else {
      EXPECT_GT(central, 1e-3);
    }
  }
}

TEST(LossRegistryTest, CreatesByNameAndReportsBadConfigs) {
  Status s;
  auto l1 =
      LossRegistry::Get().Create("l1", {{"buffer", "transmitted"}, {"target", "transmitted"}}, &s);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(l1->Name(), "l1(transmitted, transmitted)");
  EXPECT_EQ(LossRegistry::Get().Create("l2", {}, &s), nullptr);
  EXPECT_NE(s.message().find("unknown loss term 'l2'"), std::string::npos) << s.message();
  EXPECT_EQ(LossRegistry::Get().Create("tv", {{"buffer", "colour"}}, &s), nullptr);
  EXPECT_NE(s.message().find("unknown buffer 'colour'"), std::string::npos) << s.message();
  EXPECT_EQ(LossRegistry::Get().Create("render", {{"target", "gt"}}, &s), nullptr);
  EXPECT_NE(s.message().find("\"image\" or \"transmitted\""), std::string::npos) << s.message();
  // The normal consistency's variants, and their bad values.
  s = Status::Ok();
  EXPECT_NE(LossRegistry::Get().Create("normal_consistency",
                                       {{"robust_scale", 0.2}, {"one_sided", true}}, &s),
            nullptr);
  EXPECT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(LossRegistry::Get().Create("normal_consistency", {{"robust_scale", -1}}, &s), nullptr);
  EXPECT_NE(s.message().find("'robust_scale' must be finite and >= 0"), std::string::npos)
      << s.message();
  EXPECT_EQ(LossRegistry::Get().Create("normal_consistency", {{"one_sided", 1}}, &s), nullptr);
  EXPECT_NE(s.message().find("'one_sided' must be true or false"), std::string::npos)
      << s.message();
  s = Status::Ok();
  auto weighted = LossRegistry::Get().Create("normal_consistency", {{"agreement_floor", 0.3}}, &s);
  ASSERT_NE(weighted, nullptr) << s.message();
  EXPECT_TRUE(weighted->ReadsNeighbours());
  EXPECT_EQ(LossRegistry::Get().Create("normal_consistency", {{"agreement_floor", 1.5}}, &s),
            nullptr);
  EXPECT_NE(s.message().find("'agreement_floor' must be in [0, 1]"), std::string::npos)
      << s.message();
  EXPECT_EQ(LossRegistry::Get().Create("tv", {{"on_geometry", "yes"}}, &s), nullptr);
  EXPECT_NE(s.message().find("'on_geometry' must be true or false"), std::string::npos)
      << s.message();
}

TEST(ProblemTest, SumsWeightedTermsOfOneBranchAndSkipsZeroWeights) {
  Fixture f(9);
  RenderBuffers in;
  std::array<Image, kNumBuffers> fb;
  for (int b = 0; b < kNumBuffers; ++b) {
    fb[b] = f.buffers[b].Cast<float>();
    in.Set(static_cast<Buffer>(b), &fb[b]);
  }
  in.camera = &f.camera;
  const Image image = f.image.Cast<float>(), transmitted = f.transmitted.Cast<float>();
  Targets t;
  t.image = &image;
  t.transmitted = &transmitted;
  Problem problem;
  problem.AddTerm(std::make_unique<L1Loss>(), 0.8, Branch::kGaussians3D);
  problem.AddTerm(std::make_unique<DssimLoss>(), 0.2, Branch::kGaussians3D);
  problem.AddTerm(std::make_unique<EdgeAwareTvLoss>(Buffer::kTransmitted), 0.0,
                  Branch::kGaussians3D);
  problem.AddTerm(std::make_unique<L1Loss>(), 5.0, Branch::kSurfels2D);
  ASSERT_TRUE(problem.Check(Branch::kGaussians3D, in, t).ok());
  RenderGradients grad;
  std::vector<Problem::TermValue> breakdown;
  const double total = problem.Evaluate(Branch::kGaussians3D, in, t, &grad, &breakdown);
  ASSERT_EQ(breakdown.size(),
            2u);  // the zero-weight term is skipped, the 2D term is another branch
  EXPECT_NEAR(total, 0.8 * breakdown[0].value + 0.2 * breakdown[1].value, 1e-9);
  // Same as the render loss with lambda 0.8, value and gradient.
  RenderGradients ref;
  const double render = RenderLoss().Evaluate(in, t, 1.0, &ref);
  EXPECT_NEAR(total, render, 1e-6);
  for (size_t i = 0; i < grad.Get(Buffer::kColor).size(); ++i) {
    ASSERT_NEAR(grad.Get(Buffer::kColor).data()[i], ref.Get(Buffer::kColor).data()[i], 1e-9);
  }
  EXPECT_TRUE(grad.Get(Buffer::kTransmitted).empty());
  EXPECT_TRUE(problem.SetWeight("tv(transmitted, image)", Branch::kGaussians3D, 0.1));
  problem.Evaluate(Branch::kGaussians3D, in, t, &grad, &breakdown);
  EXPECT_EQ(breakdown.size(), 3u);
  // A missing target is reported by name.
  Targets none;
  const Status s = problem.Check(Branch::kGaussians3D, in, none);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("missing image"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace mgsr
