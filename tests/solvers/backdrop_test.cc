// The backdrop estimate behind `mgsr_solve --background auto`.
#include "solvers/backdrop.h"

#include <gtest/gtest.h>

#include "mgsr/core/rng.h"

namespace mgsr {
namespace {

// A photo on a grey (r, g, b) backdrop with a dark square object, touching the left border.
View Photo(const std::string& name, float r, float g, float b, bool is_test = false) {
  View v;
  v.name = name;
  v.is_test = is_test;
  v.image = Image(40, 30, 3);
  const float rgb[3] = {r, g, b};
  for (int c = 0; c < 3; ++c) {
    for (int y = 0; y < 30; ++y) {
      for (int x = 0; x < 40; ++x) {
        const bool object = x < 25 && y > 8 && y < 22;
        v.image.plane(c)[y * 40 + x] = object ? 0.1f * (c + 1) : rgb[c];
      }
    }
  }
  return v;
}

TEST(BackdropTest, FindsAUniformGreyDespiteAnObjectOnTheBorder) {
  Scene scene;
  for (int i = 0; i < 4; ++i)
    scene.views.push_back(Photo("v" + std::to_string(i), 0.6f, 0.6f, 0.6f));
  // A test view is not looked at, however it looks.
  scene.views.push_back(Photo("t", 0.1f, 0.9f, 0.1f, /*is_test=*/true));
  const Backdrop b = EstimateBackdrop(scene);
  EXPECT_TRUE(b.uniform) << b.reason;
  EXPECT_NEAR(b.level, 0.6f, 1e-6f);
  EXPECT_NEAR(b.spread, 0.0f, 1e-6f);
}

TEST(BackdropTest, RefusesVaryingColouredOrMaskedBackdrops) {
  Scene noisy;
  Rng rng(3);
  for (int i = 0; i < 3; ++i) {
    View v = Photo("n" + std::to_string(i), 0.5f, 0.5f, 0.5f);
    for (size_t k = 0; k < v.image.size(); ++k)
      v.image.data()[k] = static_cast<float>(rng.Uniform());
    noisy.views.push_back(std::move(v));
  }
  Backdrop b = EstimateBackdrop(noisy);
  EXPECT_FALSE(b.uniform);
  EXPECT_NE(b.reason.find("the photos' borders vary"), std::string::npos) << b.reason;

  Scene blue;
  blue.views = {Photo("b0", 0.2f, 0.4f, 0.8f), Photo("b1", 0.2f, 0.4f, 0.8f)};
  b = EstimateBackdrop(blue);
  EXPECT_FALSE(b.uniform);
  EXPECT_NE(b.reason.find("coloured"), std::string::npos) << b.reason;

  Scene masked;
  masked.views = {Photo("m0", 0.6f, 0.6f, 0.6f), Photo("m1", 0.6f, 0.6f, 0.6f)};
  masked.views[1].mask = Image(40, 30, 1);
  b = EstimateBackdrop(masked);
  EXPECT_FALSE(b.uniform);
  EXPECT_EQ(b.reason, "m1 has a mask or alpha");

  EXPECT_FALSE(EstimateBackdrop(Scene()).uniform);
}

}  // namespace
}  // namespace mgsr
