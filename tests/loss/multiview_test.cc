// The multi-view terms: the plane-induced warp against a numerically intersected plane, the terms
// on exactly rendered views of a textured plane, the forward-backward reprojection's derivative,
// and neighbour selection on a known camera layout. (Their gradients on random inputs are checked
// by loss_test's harness with every registered term.)
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <set>

#include "mgsr/core/rng.h"
#include "mgsr/io/view_neighbours.h"
#include "mgsr/loss/multiview_depth_loss.h"
#include "mgsr/loss/multiview_geometry.h"
#include "mgsr/loss/multiview_ncc_loss.h"
#include "mgsr/loss/normal_consistency_loss.h"
#include "mgsr/loss/parallel_pixels.h"
#include "test_util.h"

namespace mgsr {
namespace {

// A textured plane through `origin` with unit normal `n`, seen exactly by a camera: z-depth,
// the normal (turned to the camera) and a smooth grey texture of the world position.
struct PlaneView {
  ImageD depth, normal, alpha, gray;
};

double Texture(const Eigen::Vector3d& X) {
  return 0.5 + 0.2 * std::sin(21.0 * X.x() + 4.0 * X.y()) * std::cos(15.0 * X.z() - 1.2 * X.x()) +
         0.15 * std::sin(33.0 * X.y() + 9.0 * X.z());
}

PlaneView RenderPlane(const Camera& cam, const Eigen::Vector3d& origin, const Eigen::Vector3d& n,
                      double depth_scale = 1.0) {
  PlaneView v{ImageD(cam.width, cam.height, 1), ImageD(cam.width, cam.height, 3),
              ImageD(cam.width, cam.height, 1), ImageD(cam.width, cam.height, 1)};
  const Eigen::Vector3d C = cam.Center();
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const Eigen::Vector3d w = cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5);
      const double t = n.dot(origin - C) / n.dot(w);  // z-depth (w has camera z = 1)
      const Eigen::Vector3d X = C + t * w;
      v.depth.at(0, y, x) = t * depth_scale;
      const Eigen::Vector3d nn = n.dot(w) < 0 ? n : Eigen::Vector3d(-n);
      for (int c = 0; c < 3; ++c) v.normal.at(c, y, x) = nn[c];
      v.alpha.at(0, y, x) = 1.0;
      v.gray.at(0, y, x) = Texture(X);
    }
  }
  return v;
}

TEST(MultiviewGeometryTest, PlaneWarpMatchesTheIntersectedPlane) {
  const Camera ref =
      LookAtCamera({0.3, -3, 0.6}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64, 48, 60, 62);
  const Camera nb =
      LookAtCamera({1.1, -2.8, 0.9}, {0.1, 0, 0}, Eigen::Vector3d::UnitZ(), 64, 48, 58, 58);
  const Eigen::Vector3d origin(0.05, 0.1, -0.02), n = Eigen::Vector3d(0.2, -1.0, 0.35).normalized();
  const Eigen::Vector3d C = ref.Center();
  auto point_of = [&](const Eigen::Vector2d& q) {
    const Eigen::Vector3d w = ref.R.transpose() * ref.PixelToRay(q.x(), q.y());
    return Eigen::Vector3d(C + (n.dot(origin - C) / n.dot(w)) * w);
  };
  const Eigen::Vector2d p(30.5, 20.5);
  const double D = ref.WorldToCamera(point_of(p)).z();
  double worst = 0;
  for (double dy = -5; dy <= 5; dy += 2.5) {
    for (double dx = -5; dx <= 5; dx += 2.5) {
      const Eigen::Vector2d q = p + Eigen::Vector2d(dx, dy);
      Eigen::Vector2d warped;
      ASSERT_TRUE(multiview::WarpThroughPlane(ref, nb, p, D, n, q, &warped));
      worst = std::max(worst, (warped - nb.WorldToPixel(point_of(q))).norm());
      // The other side of the normal is the same plane.
      Eigen::Vector2d flipped;
      ASSERT_TRUE(multiview::WarpThroughPlane(ref, nb, p, D, -n, q, &flipped));
      EXPECT_NEAR((flipped - warped).norm(), 0.0, 1e-9);
    }
  }
  EXPECT_LT(worst, 1e-9);
  // A wrong depth moves every warped pixel off the plane's.
  Eigen::Vector2d off;
  ASSERT_TRUE(multiview::WarpThroughPlane(ref, nb, p, 1.05 * D, n, p, &off));
  EXPECT_GT((off - nb.WorldToPixel(point_of(p))).norm(), 0.5);
}

// Three views of a textured plane, 64 x 48 pixels (or `scale` times that on each side, the same
// field of view).
struct TwoViewScene {
  explicit TwoViewScene(int scale = 1)
      : ref(LookAtCamera({0.3, -3, 0.6}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64 * scale,
                         48 * scale, 60 * scale, 60 * scale)),
        nb{LookAtCamera({1.0, -2.85, 0.8}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64 * scale,
                        48 * scale, 60 * scale, 60 * scale),
           LookAtCamera({-0.5, -2.9, 0.2}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 64 * scale,
                        48 * scale, 60 * scale, 60 * scale)},
        view(RenderPlane(ref, origin, n)),
        nb_view{RenderPlane(nb[0], origin, n), RenderPlane(nb[1], origin, n)} {
    in.camera = &ref;
    in.Set(Buffer::kDepth, &view.depth);
    in.Set(Buffer::kNormal, &view.normal);
    in.Set(Buffer::kAlpha, &view.alpha);
    targets.gray = &view.gray;
    for (int k = 0; k < 2; ++k)
      targets.neighbours[k] = {&nb[k], &nb_view[k].gray, &nb_view[k].depth};
    targets.num_neighbours = 2;
  }
  Eigen::Vector3d origin{0, 0, 0}, n = Eigen::Vector3d(0.15, -1.0, 0.3).normalized();
  Camera ref;
  std::array<Camera, 2> nb;
  PlaneView view;
  std::array<PlaneView, 2> nb_view;
  RenderBuffersD in;
  TargetsD targets;
};

// Both terms split their rows over threads on images of kParallelPixels or more: the same value
// and gradient on one thread and on three (each thread once summed into a row table it did not
// have, and crashed).
TEST(MultiviewTermsTest, LargeImagesGiveTheSameResultOnAnyThreadCount) {
  TwoViewScene s(3);  // 192 x 144
  ASSERT_GE(static_cast<int64_t>(s.ref.width) * s.ref.height, kParallelPixels);
  const PlaneView far = RenderPlane(s.ref, s.origin, s.n, 1.01);
  s.in.Set(Buffer::kDepth, &far.depth);
  MultiviewNccConfig nc;
  nc.check_occlusion = true;
  const MultiviewNccLoss ncc(nc);
  const MultiviewDepthLoss depth;
  const int saved = omp_get_max_threads();
  for (const LossTerm* term : std::array<const LossTerm*, 2>{&ncc, &depth}) {
    double value[2];
    RenderGradientsD g[2];
    for (int k = 0; k < 2; ++k) {
      omp_set_num_threads(k == 0 ? 1 : 3);
      value[k] = term->Evaluate(s.in, s.targets, 1.0, &g[k]);
    }
    omp_set_num_threads(saved);
    EXPECT_GT(value[0], 0) << term->Name();
    EXPECT_EQ(value[0], value[1]) << term->Name();
    const ImageD& a = g[0].Get(Buffer::kDepth);
    const ImageD& b = g[1].Get(Buffer::kDepth);
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a.data()[i], b.data()[i]) << term->Name() << i;
  }
}

TEST(MultiviewNccTest, ExactPlaneAgreesAndAWrongDepthDoesNot) {
  TwoViewScene s;
  const MultiviewNccLoss ncc;
  ASSERT_TRUE(ncc.Check(RenderBuffers(), Targets()).ok() == false);  // needs its inputs
  const double exact = ncc.Evaluate(s.in, s.targets, 1.0, nullptr);
  // Only bilinear interpolation separates the warped patch from the truth.
  EXPECT_LT(exact, 0.01);
  // The depth 10% too far: the patches no longer match (the occlusion test off, which would
  // otherwise drop every pair that disagrees).
  MultiviewNccConfig c;
  c.check_occlusion = false;
  c.max_pair_loss = 2;  // every pair: at 10% off many no longer correlate (the outlier test below)
  const MultiviewNccLoss no_occlusion(c);
  const PlaneView far = RenderPlane(s.ref, s.origin, s.n, 1.1);
  s.in.Set(Buffer::kDepth, &far.depth);
  const double wrong = no_occlusion.Evaluate(s.in, s.targets, 1.0, nullptr);
  EXPECT_GT(wrong, 10 * exact + 0.02);
  // With the occlusion test every centre reprojects through the neighbours' (right) depth more
  // than a pixel off: all skipped.
  MultiviewNccConfig occlusion = c;
  occlusion.check_occlusion = true;
  EXPECT_EQ(MultiviewNccLoss(occlusion).Evaluate(s.in, s.targets, 1.0, nullptr), 0.0);
  // Its gradient pushes the depth back: a step against it lowers the loss.
  RenderGradientsD g;
  no_occlusion.Evaluate(s.in, s.targets, 1.0, &g);
  ImageD stepped = far.depth;
  const ImageD& gd = g.Get(Buffer::kDepth);
  double norm2 = 0;
  for (size_t i = 0; i < gd.size(); ++i) norm2 += gd.data()[i] * gd.data()[i];
  ASSERT_GT(norm2, 0);
  for (size_t i = 0; i < stepped.size(); ++i)
    stepped.data()[i] -= 0.01 * gd.data()[i] / std::sqrt(norm2);
  s.in.Set(Buffer::kDepth, &stepped);
  EXPECT_LT(no_occlusion.Evaluate(s.in, s.targets, 1.0, nullptr), wrong);
}

// The patch test: a patch counts only where the view's own render puts it on the centre's plane.
// On a plane whose rendered depth is a little noisy every patch passes (the value is the one
// without the test) and the gradient matches central differences with the test on; across a
// depth step, or next to an uncovered pixel, the patches that reach over it are skipped.
TEST(MultiviewNccTest, OnlyPatchesOnTheCentresPlaneCount) {
  TwoViewScene s;
  MultiviewNccConfig on;
  on.check_occlusion = false;  // isolate the patch test
  MultiviewNccConfig off = on;
  off.max_plane_offset_px = 0;
  const MultiviewNccLoss with_test(on), without_test(off);
  // Depth noise of 5% of a pixel footprint (z / fx) on a slightly wrong plane (so the gradient
  // is not at a minimum).
  ImageD noisy = RenderPlane(s.ref, s.origin, s.n, 1.02).depth;
  Rng rng(4);
  for (size_t i = 0; i < noisy.size(); ++i)
    noisy.data()[i] *= 1.0 + 0.05 * rng.Uniform(-1, 1) / s.ref.fx;
  s.in.Set(Buffer::kDepth, &noisy);
  const double value = with_test.Evaluate(s.in, s.targets, 1.0, nullptr);
  EXPECT_GT(value, 0.0);
  EXPECT_EQ(value, without_test.Evaluate(s.in, s.targets, 1.0, nullptr));
  RenderGradientsD g;
  with_test.Evaluate(s.in, s.targets, 1.0, &g);
  const ImageD& gd = g.Get(Buffer::kDepth);
  int nonzero = 0;
  for (size_t i = 0; i < noisy.size(); i += 7) {
    const double numeric = testing::CentralDifference(
        [&] { return with_test.Evaluate(s.in, s.targets, 1.0, nullptr); }, &noisy.data()[i]);
    EXPECT_NEAR(gd.data()[i], numeric, 1e-6 + 1e-5 * std::abs(numeric)) << "depth[" << i << "]";
    nonzero += std::abs(numeric) > 1e-9;
  }
  EXPECT_GT(nonzero, 10);

  // A step: columns from 33 on 10% farther (a plane too: scaled from the camera centre). Centres
  // are on a grid of 3 with a radius of 3, so the centres at columns 30 and 33 reach over the step
  // and their pairs are skipped; 27 and 36 lie on one side each and count.
  ImageD step = RenderPlane(s.ref, s.origin, s.n).depth;
  for (int y = 0; y < step.height(); ++y)
    for (int x = 33; x < step.width(); ++x) step.at(0, y, x) *= 1.1;
  s.in.Set(Buffer::kDepth, &step);
  RenderGradientsD g_on, g_off;
  const double v_on = with_test.Evaluate(s.in, s.targets, 1.0, &g_on);
  const double v_off = without_test.Evaluate(s.in, s.targets, 1.0, &g_off);
  EXPECT_LT(v_on, v_off);
  const int y = 21;  // a row of centres
  for (int x : {30, 33}) {
    EXPECT_EQ(g_on.Get(Buffer::kDepth).at(0, y, x), 0.0) << x;
    EXPECT_NE(g_off.Get(Buffer::kDepth).at(0, y, x), 0.0) << x;
  }
  EXPECT_NE(g_on.Get(Buffer::kDepth).at(0, y, 36), 0.0);
  EXPECT_NE(g_on.Get(Buffer::kDepth).at(0, y, 27), 0.0);

  // An uncovered pixel: the patches that contain it are skipped, the rest are not.
  ImageD wrong = RenderPlane(s.ref, s.origin, s.n, 1.05).depth;
  s.in.Set(Buffer::kDepth, &wrong);
  ImageD alpha = s.view.alpha;
  alpha.at(0, 21, 22) = 0.2;
  s.in.Set(Buffer::kAlpha, &alpha);
  RenderGradientsD g_hole;
  with_test.Evaluate(s.in, s.targets, 1.0, &g_hole);
  for (int x : {21, 24}) EXPECT_EQ(g_hole.Get(Buffer::kDepth).at(0, 21, x), 0.0) << x;
  EXPECT_NE(g_hole.Get(Buffer::kDepth).at(0, 21, 27), 0.0);
  EXPECT_NE(g_hole.Get(Buffer::kDepth).at(0, 21, 18), 0.0);
}

// The fitted-plane test (fit_plane): it asks whether the patch is one surface, not whether the
// rendered normal agrees with the depth. On the exact plane's depth with rendered normals tilted
// 20 degrees, the centre-normal test skips every patch and the fitted one none (its value is that
// of no test); across a step of 10% in depth the fitted test still skips the centres that reach
// over it.
TEST(MultiviewNccTest, FittedPlaneTestKeepsTiltedNormalsAndSkipsSteps) {
  TwoViewScene s;
  MultiviewNccConfig centre, fitted, none;
  centre.check_occlusion = fitted.check_occlusion = none.check_occlusion = false;
  centre.max_pair_loss = fitted.max_pair_loss = none.max_pair_loss = 2;
  fitted.fit_plane = true;
  none.max_plane_offset_px = 0;
  const MultiviewNccLoss by_centre(centre), by_fit(fitted), without(none);
  const Eigen::Vector3d axis = s.n.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d tilted_n = Eigen::AngleAxisd(20.0 * M_PI / 180.0, axis) * s.n;
  ImageD tilted = s.view.normal;
  for (int y = 0; y < tilted.height(); ++y) {
    for (int x = 0; x < tilted.width(); ++x) {
      const double sign = tilted.at(0, y, x) * s.n.x() + tilted.at(1, y, x) * s.n.y() +
                                      tilted.at(2, y, x) * s.n.z() >
                                  0
                              ? 1.0
                              : -1.0;
      for (int c = 0; c < 3; ++c) tilted.at(c, y, x) = sign * tilted_n[c];
    }
  }
  s.in.Set(Buffer::kNormal, &tilted);
  EXPECT_EQ(by_centre.Evaluate(s.in, s.targets, 1.0, nullptr), 0.0);
  const double v_fit = by_fit.Evaluate(s.in, s.targets, 1.0, nullptr);
  EXPECT_GT(v_fit, 0.0);
  EXPECT_EQ(v_fit, without.Evaluate(s.in, s.targets, 1.0, nullptr));

  ImageD step = s.view.depth;
  for (int y = 0; y < step.height(); ++y)
    for (int x = 33; x < step.width(); ++x) step.at(0, y, x) *= 1.1;
  s.in.Set(Buffer::kDepth, &step);
  RenderGradientsD g_fit;
  by_fit.Evaluate(s.in, s.targets, 1.0, &g_fit);
  const int y = 21;
  for (int x : {30, 33}) EXPECT_EQ(g_fit.Get(Buffer::kDepth).at(0, y, x), 0.0) << x;
  EXPECT_NE(g_fit.Get(Buffer::kDepth).at(0, y, 27), 0.0);
  EXPECT_NE(g_fit.Get(Buffer::kDepth).at(0, y, 36), 0.0);
}

// Outliers: a pair whose patches do not correlate (here the first neighbour's photo is the
// negative of the truth, NCC = -1, as where a highlight covers the texture in one view only) is
// left out by default and counted with max_pair_loss = 2. What is left is the second neighbour's
// pairs: half the value and gradient of a scene with the second neighbour in both places (the
// normaliser counts both neighbours), on the exact plane and on a wrong one.
TEST(MultiviewNccTest, PairsWhosePatchesDoNotCorrelateAreLeftOut) {
  TwoViewScene s;
  MultiviewNccConfig keep_all;
  keep_all.check_occlusion = false;
  keep_all.max_pair_loss = 2;
  MultiviewNccConfig by_default;
  EXPECT_EQ(by_default.max_pair_loss, 0.9);
  EXPECT_FALSE(by_default.check_occlusion);
  const MultiviewNccLoss robust(by_default), plain(keep_all);
  // On the exact scene nothing is an outlier.
  EXPECT_EQ(robust.Evaluate(s.in, s.targets, 1.0, nullptr),
            plain.Evaluate(s.in, s.targets, 1.0, nullptr));
  TargetsD second = s.targets;
  second.neighbours[0] = second.neighbours[1];
  ImageD negative = s.nb_view[0].gray;
  for (size_t i = 0; i < negative.size(); ++i) negative.data()[i] = 1.0 - negative.data()[i];
  s.targets.neighbours[0].gray = &negative;
  // Counted, each pair with the first neighbour adds about 2 / M.
  EXPECT_GT(plain.Evaluate(s.in, s.targets, 1.0, nullptr), 0.5);
  const PlaneView far = RenderPlane(s.ref, s.origin, s.n, 1.05);
  for (const ImageD* depth : std::array<const ImageD*, 2>{&s.view.depth, &far.depth}) {
    s.in.Set(Buffer::kDepth, depth);
    RenderGradientsD g_robust, g_second;
    const double v_robust = robust.Evaluate(s.in, s.targets, 1.0, &g_robust);
    const double v_second = plain.Evaluate(s.in, second, 1.0, &g_second);
    EXPECT_GT(v_second, 0);
    EXPECT_NEAR(v_robust, 0.5 * v_second, 1e-12 * v_second);
    const ImageD& a = g_robust.Get(Buffer::kDepth);
    const ImageD& b = g_second.Get(Buffer::kDepth);
    double worst = 0, largest = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      worst = std::max(worst, std::abs(a.data()[i] - 0.5 * b.data()[i]));
      largest = std::max(largest, std::abs(b.data()[i]));
    }
    EXPECT_GT(largest, 0);
    EXPECT_LT(worst, 1e-9 * largest);
  }
}

// A large image: the centres' grid widens so that it holds at most max_centres pixels (512 x 384
// at stride 3 would hold 21,888; a grid of 4 holds 12,288), and every centre that pulls lies on
// it. A small image keeps its stride.
TEST(MultiviewNccTest, LargeImagesSampleAtMostMaxCentres) {
  TwoViewScene s(8);  // 512 x 384
  const PlaneView far = RenderPlane(s.ref, s.origin, s.n, 1.01);
  s.in.Set(Buffer::kDepth, &far.depth);
  MultiviewNccConfig bounded;
  EXPECT_EQ(bounded.max_centres, 16384);
  MultiviewNccConfig every = bounded;
  every.max_centres = 1000000000;
  const MultiviewNccLoss a(bounded), b(every);
  EXPECT_EQ(a.Stride(512, 384), 4);
  EXPECT_EQ(b.Stride(512, 384), 3);
  EXPECT_EQ(a.Stride(64, 48), 3);
  for (const MultiviewNccLoss* term : {&a, &b}) {
    RenderGradientsD g;
    EXPECT_GT(term->Evaluate(s.in, s.targets, 1.0, &g), 0);
    const ImageD& gd = g.Get(Buffer::kDepth);
    const int stride = term->Stride(512, 384);
    int pulled = 0, off_grid = 0;
    for (int y = 0; y < gd.height(); ++y) {
      for (int x = 0; x < gd.width(); ++x) {
        if (gd.at(0, y, x) == 0) continue;
        ++pulled;
        off_grid += (x % stride != 0 || y % stride != 0);
      }
    }
    EXPECT_EQ(off_grid, 0);
    EXPECT_GT(pulled, 5000);
    if (term == &a) {
      EXPECT_LE(pulled, 16384);
    } else {
      EXPECT_GT(pulled, 16384);
    }
  }
}

// The agreement map: near 1 at the centres of the exact plane whose patch fits in the frame, 0
// where no neighbour could be compared (the frame's border), lower on a plane 10% too far, and 0
// where both neighbours see the negative of the texture. Its value is the term's.
TEST(MultiviewNccTest, AgreementIsHighOnTheExactPlaneAndLowOffIt) {
  TwoViewScene s;
  const MultiviewNccLoss ncc;
  std::vector<double> exact;
  EXPECT_EQ(ncc.Agreement(s.in, s.targets, &exact), ncc.Evaluate(s.in, s.targets, 1.0, nullptr));
  const int stride = ncc.Stride(64, 48), cols = (64 + stride - 1) / stride;
  ASSERT_EQ(exact.size(), static_cast<size_t>(cols) * ((48 + stride - 1) / stride));
  int agreeing = 0;
  double mean_exact = 0;
  for (size_t c = 0; c < exact.size(); ++c) {
    const int x = static_cast<int>(c % cols) * stride, y = static_cast<int>(c / cols) * stride;
    const int r = ncc.config().patch_radius;
    if (x < r || y < r || x + r >= 64 || y + r >= 48) {
      EXPECT_EQ(exact[c], 0.0) << x << " " << y;  // the patch leaves the frame
      continue;
    }
    EXPECT_LE(exact[c], 1.0);
    agreeing += exact[c] > 0.95;
    mean_exact += exact[c];
  }
  EXPECT_GT(agreeing, 100);
  mean_exact /= exact.size();
  const PlaneView far = RenderPlane(s.ref, s.origin, s.n, 1.1);
  s.in.Set(Buffer::kDepth, &far.depth);
  std::vector<double> wrong;
  ncc.Agreement(s.in, s.targets, &wrong);
  double mean_wrong = 0;
  for (double a : wrong) mean_wrong += a;
  mean_wrong /= wrong.size();
  EXPECT_LT(mean_wrong, 0.7 * mean_exact);
  s.in.Set(Buffer::kDepth, &s.view.depth);
  std::array<ImageD, 2> negative{s.nb_view[0].gray, s.nb_view[1].gray};
  for (int k = 0; k < 2; ++k) {
    for (size_t i = 0; i < negative[k].size(); ++i)
      negative[k].data()[i] = 1.0 - negative[k].data()[i];
    s.targets.neighbours[k].gray = &negative[k];
  }
  std::vector<double> contradicted;
  ncc.Agreement(s.in, s.targets, &contradicted);
  for (double a : contradicted) EXPECT_LT(a, 0.05);
}

// The normal consistency weighted by agreement: each pixel's weight is mask x (1 - (1 - f) a) with
// a the agreement at the nearest centre of the grid; off at f = 1 and where the view has no
// neighbours. The weight is a constant of the step: value and gradient are those of the plain
// term with the weight as its mask (whose gradient loss_test checks against numeric
// differentiation), on normals that disagree with the depth.
TEST(NormalConsistencyAgreementTest, WeightFallsToTheFloorWhereTheViewsAgree) {
  TwoViewScene s;
  ImageD mask(64, 48, 1);
  Rng rng(7);
  for (size_t i = 0; i < mask.size(); ++i) mask.data()[i] = 0.5 + 0.5 * rng.Uniform();
  s.targets.mask = &mask;
  NormalConsistencyOptions o;
  EXPECT_EQ(o.agreement_floor, 1.0);
  std::vector<double> weight;
  EXPECT_FALSE(NormalConsistencyLoss(o).ReadsNeighbours());
  EXPECT_FALSE(NormalConsistencyLoss(o).PixelWeights(s.in, s.targets, &weight));
  o.agreement_floor = 0.2;
  const NormalConsistencyLoss term(o);
  EXPECT_TRUE(term.ReadsNeighbours());
  TargetsD alone = s.targets;
  alone.num_neighbours = 0;
  EXPECT_FALSE(term.PixelWeights(s.in, alone, &weight));
  ASSERT_TRUE(term.PixelWeights(s.in, s.targets, &weight));
  const MultiviewNccLoss ncc(NormalConsistencyLoss::AgreementConfig());
  EXPECT_TRUE(ncc.config().fit_plane);
  std::vector<double> agreement;
  ncc.Agreement(s.in, s.targets, &agreement);
  const int stride = ncc.Stride(64, 48), cols = (64 + stride - 1) / stride;
  int at_floor = 0, full = 0;
  for (int y = 0; y < 48; ++y) {
    for (int x = 0; x < 64; ++x) {
      const size_t i = static_cast<size_t>(y) * 64 + x;
      const int cx = std::min(cols - 1, (x + stride / 2) / stride);
      const int cy = std::min((48 + stride - 1) / stride - 1, (y + stride / 2) / stride);
      const double a = agreement[static_cast<size_t>(cy) * cols + cx];
      EXPECT_NEAR(weight[i], mask.data()[i] * (1.0 - 0.8 * a), 1e-15);
      at_floor += weight[i] < 0.25 * mask.data()[i];
      full += weight[i] == mask.data()[i];
    }
  }
  EXPECT_GT(at_floor, 1000);  // the exact plane's interior
  EXPECT_GT(full, 100);       // the border, where no patch is compared
  // Normals tilted away from the depth's: the term is not zero and pulls both.
  ImageD tilted = s.view.normal;
  for (size_t i = 0; i < 64 * 48; ++i) tilted.plane(0)[i] += 0.3 * rng.Uniform();
  s.in.Set(Buffer::kNormal, &tilted);
  ASSERT_TRUE(term.PixelWeights(s.in, s.targets, &weight));
  ImageD as_mask(64, 48, 1);
  for (size_t i = 0; i < as_mask.size(); ++i) as_mask.data()[i] = weight[i];
  TargetsD masked = s.targets;
  masked.mask = &as_mask;
  masked.num_neighbours = 0;
  RenderGradientsD g_term, g_plain;
  const double v_term = term.Evaluate(s.in, s.targets, 1.0, &g_term);
  const double v_plain = NormalConsistencyLoss().Evaluate(s.in, masked, 1.0, &g_plain);
  EXPECT_GT(v_term, 0);
  EXPECT_EQ(v_term, v_plain);
  for (Buffer b : {Buffer::kDepth, Buffer::kNormal}) {
    const ImageD& a = g_term.Get(b);
    const ImageD& c = g_plain.Get(b);
    ASSERT_EQ(a.size(), c.size());
    for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a.data()[i], c.data()[i]) << i;
  }
}

TEST(MultiviewDepthTest, ExactPlaneReprojectsOntoItselfAndTheDerivativeIsExact) {
  TwoViewScene s;
  const MultiviewDepthLoss depth;
  // Bilinear depth is not exactly the plane's (depth is not linear in pixels): a thousandth.
  EXPECT_LT(depth.Evaluate(s.in, s.targets, 1.0, nullptr), 1e-3);
  const PlaneView far = RenderPlane(s.ref, s.origin, s.n, 1.01);
  s.in.Set(Buffer::kDepth, &far.depth);
  EXPECT_GT(depth.Evaluate(s.in, s.targets, 1.0, nullptr), 0.05);
  // ForwardBackward's derivative against central differences, off the exact depth.
  const Eigen::Vector2d p(25.5, 19.5);
  const double D = far.depth.at(0, 19, 25);
  double e, de;
  ASSERT_TRUE(multiview::ForwardBackward(s.ref, s.nb[0], s.nb_view[0].depth, p, D, &e, &de));
  double ep, em;
  const double h = 1e-6;
  ASSERT_TRUE(
      multiview::ForwardBackward(s.ref, s.nb[0], s.nb_view[0].depth, p, D + h, &ep, nullptr));
  ASSERT_TRUE(
      multiview::ForwardBackward(s.ref, s.nb[0], s.nb_view[0].depth, p, D - h, &em, nullptr));
  EXPECT_GT(e, 0.1);
  EXPECT_NEAR(de, (ep - em) / (2 * h), 1e-5 * std::max(1.0, std::abs(de)));
}

TEST(ViewNeighboursTest, RingOfCamerasPicksTheAdjacentOnes) {
  // 24 cameras on a circle 15 degrees apart, all looking at a ball of points: each view's two
  // neighbours are the cameras beside it, never one across the circle.
  Scene scene;
  const int n = 24;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    View v;
    v.name = "v" + std::to_string(i);
    v.camera = LookAtCamera({3 * std::cos(a), 3 * std::sin(a), 0.4}, {0, 0, 0},
                            Eigen::Vector3d::UnitZ(), 64, 64, 60, 60);
    scene.views.push_back(v);
  }
  for (int i = 0; i < 500; ++i) {
    const double u = 2 * M_PI * ((i * 0.618034) - std::floor(i * 0.618034)), z = -1 + 2.0 * i / 500;
    const double r = std::sqrt(1 - z * z);
    scene.points.emplace_back(0.6 * r * std::cos(u), 0.6 * r * std::sin(u), 0.6 * z);
  }
  NeighbourOptions o;
  o.count = 2;
  const auto nbs = SelectNeighbours(scene, o);
  ASSERT_EQ(nbs.size(), static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    ASSERT_EQ(nbs[i].size(), 2u) << i;
    const std::set<int> got(nbs[i].begin(), nbs[i].end());
    EXPECT_EQ(got, (std::set<int>{(i + 1) % n, (i + n - 1) % n})) << "view " << i;
  }
  // Test views get neighbours too, but are never anyone's neighbour.
  scene.views[5].is_test = true;
  const auto with_test = SelectNeighbours(scene, o);
  EXPECT_EQ(with_test[5].size(), 2u);
  for (int i = 0; i < n; ++i)
    for (int u : with_test[i]) EXPECT_NE(u, 5);
}

}  // namespace
}  // namespace mgsr
