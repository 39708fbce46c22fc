#include "mgsr/eval/image_metrics.h"

#include <gtest/gtest.h>

#include <cmath>

#include "mgsr/core/rng.h"
#include "test_util.h"

namespace mgsr {
namespace {

Image RandomImage(int w, int h, int c, uint64_t seed) {
  Rng rng(seed);
  Image im(w, h, c);
  for (size_t i = 0; i < im.size(); ++i) im.data()[i] = static_cast<float>(rng.Uniform());
  return im;
}

// Direct, non-separable SSIM in double precision: an independent reference for the fast one.
double SlowSsim(const Image& a, const Image& b) {
  const ImageD da = a.Cast<double>(), db = b.Cast<double>();
  double total = 0;
  for (int c = 0; c < a.channels(); ++c)
    total += testing::DirectSsimSum(da.plane(c), db.plane(c), a.width(), a.height());
  return total / a.size();
}

TEST(ImageMetricsTest, PsnrOfAKnownError) {
  Image a(8, 8, 3, 0.5f), b(8, 8, 3, 0.6f);
  EXPECT_NEAR(Psnr(a, b), 20.0, 1e-5);  // MSE 0.01
  EXPECT_TRUE(std::isinf(Psnr(a, a)));
}

TEST(ImageMetricsTest, SsimOfIdenticalImagesIsOne) {
  const Image a = RandomImage(20, 15, 3, 1);
  EXPECT_NEAR(Ssim(a, a), 1.0, 1e-6);
}

TEST(ImageMetricsTest, SsimMatchesADirectImplementation) {
  const Image a = RandomImage(23, 17, 3, 2);
  Image b = a;
  Rng rng(5);
  for (size_t i = 0; i < b.size(); ++i)
    b.data()[i] = 0.7f * b.data()[i] + 0.2f * static_cast<float>(rng.Uniform());
  const double fast = Ssim(a, b), slow = SlowSsim(a, b);
  EXPECT_NEAR(fast, slow, 1e-5);
  EXPECT_LT(fast, 0.95);
}

}  // namespace
}  // namespace mgsr

#include "mgsr/eval/exposure_alignment.h"

namespace mgsr {
namespace {

TEST(ExposureAlignmentTest, RecoversAKnownAffineColourTransform) {
  const Image render = RandomImage(32, 24, 3, 11);
  Eigen::Matrix<double, 3, 4> truth;
  truth << 1.8, 0.1, 0.0, 0.02, 0.0, 1.5, 0.05, -0.01, 0.02, 0.0, 0.7, 0.03;
  const Image target = ApplyAffineColor(render, truth);
  const AlignedScores s = ExposureAlignedScores(render, target);
  EXPECT_NEAR((s.transform - truth).norm(), 0.0, 1e-4);
  EXPECT_GT(s.psnr, 50.0);  // issue 10: a render against a gain-scaled copy of itself
  EXPECT_GT(s.ssim, 0.9999);
  EXPECT_LT(Psnr(render, target), 20.0);  // unaligned, the same pair scores badly
}

TEST(ExposureAlignmentTest, MaskLimitsTheFitAndDegenerateInputsFallBackToIdentity) {
  const Image render = RandomImage(16, 16, 3, 12);
  Image target = render;
  Image mask(16, 16, 1, 0.0f);
  for (int y = 0; y < 8; ++y) {
    for (int x = 0; x < 16; ++x) mask.at(0, y, x) = 1.0f;
  }
  for (int y = 8; y < 16; ++y) {
    for (int x = 0; x < 16; ++x) {
      for (int c = 0; c < 3; ++c) target.at(c, y, x) = 0.0f;  // background differs; masked out
    }
  }
  const auto M = FitAffineColor(render, target, &mask);
  EXPECT_NEAR((M.leftCols<3>() - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-6);
  // Applied inside the mask only: the background keeps the render's values.
  Eigen::Matrix<double, 3, 4> gain = Eigen::Matrix<double, 3, 4>::Zero();
  gain.leftCols<3>() = 2 * Eigen::Matrix3d::Identity();
  const Image applied = ApplyAffineColor(render, gain, &mask);
  EXPECT_FLOAT_EQ(applied.at(1, 2, 3), 2 * render.at(1, 2, 3));
  EXPECT_FLOAT_EQ(applied.at(1, 12, 3), render.at(1, 12, 3));
  const Image empty_mask(16, 16, 1, 0.0f);
  const auto I = FitAffineColor(render, target, &empty_mask);
  EXPECT_EQ(I.leftCols<3>(), Eigen::Matrix3d::Identity());
}

}  // namespace
}  // namespace mgsr
