// Density strategies: the registry, the MCMC strategy's moment matching (by its formula and on
// rendered images), relocation, growth under the cap, regulariser gradients (against numeric
// differentiation) and position noise, and a solve with it.
#include "solvers/density_strategy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <type_traits>

#include "mgsr/io/scene.h"
#include "mgsr/model/activations.h"
#include "mgsr/render/gaussian_renderer.h"
#include "mgsr/render/surfel_renderer.h"
#include "mgsr/synth/synthetic_scene.h"
#include "solvers/density_mcmc.h"
#include "solvers/density_reference.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/primitive_types.h"
#include "test_util.h"

namespace mgsr {
namespace {

// n Gaussians on a line, unit quaternions, scales 0.01, opacity 0.5; Adam state with non-zero
// moments so zeroing shows.
GaussianModel LineOfGaussians(size_t n, Adam* adam) {
  GaussianModel m;
  m.max_sh_degree = 0;
  m.Resize(n);
  for (size_t i = 0; i < n; ++i) {
    m.means[3 * i] = static_cast<float>(i);
    m.quats[4 * i] = 1.0f;
    for (int k = 0; k < 3; ++k) m.log_scales[3 * i + k] = std::log(0.01f);
    m.opacity_logits[i] = 0.0f;
    m.ref_opacity_logits[i] = -2.0f;
    m.sh[3 * i] = static_cast<float>(i);
  }
  GaussianModel g = m;
  for (std::vector<float>* b : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh,
                                &g.ref_sh, &g.ref_opacity_logits, &g.beta_logits})
    std::fill(b->begin(), b->end(), 1.0f);
  adam->Step(m.Blocks(), g.Blocks(),
             [](const std::string&, int, std::vector<float>* r) { r->assign(r->size(), 1e-9f); });
  return m;
}

DensityContext McmcContext(size_t cap) {
  DensityContext c;
  c.schedule = {0, 1000, 10, 100000, 0.005f};
  c.density.max_primitives = cap;
  c.extent = 1;
  return c;
}

// The MCMC strategy capped at `cap`, relocating only (no growth).
McmcDensity RelocatingMcmc(size_t cap) {
  McmcOptions mo;
  mo.growth = 0;
  return McmcDensity(McmcContext(cap), mo);
}

DensityStep EventStep(int iteration) {
  DensityStep s;
  s.iteration = iteration;
  s.position_lr = 0;  // no noise unless a test asks
  return s;
}

TEST(DensityStrategyTest, RegistryCreatesBuiltinsAndRefusesBadNamesAndConfigs) {
  DensityStrategyRegistry& r = DensityStrategyRegistry::Get();
  Status s;
  EXPECT_NE(r.Create("reference", McmcContext(0), nullptr, &s), nullptr) << s.message();
  EXPECT_NE(r.Create("mcmc", McmcContext(100), {{"growth", 0.1}}, &s), nullptr) << s.message();
  EXPECT_EQ(r.Create("nope", McmcContext(100), nullptr, &s), nullptr);
  EXPECT_NE(s.message().find("unknown density strategy \"nope\""), std::string::npos);
  EXPECT_NE(s.message().find("mcmc"), std::string::npos) << "lists the known names";
  EXPECT_EQ(r.Create("mcmc", McmcContext(0), nullptr, &s), nullptr);
  EXPECT_NE(s.message().find("needs a budget"), std::string::npos) << s.message();
  EXPECT_EQ(r.Create("mcmc", McmcContext(10), {{"grwoth", 0.1}}, &s), nullptr);
  EXPECT_NE(s.message().find("unknown key \"grwoth\""), std::string::npos) << s.message();
  EXPECT_EQ(r.Create("mcmc", McmcContext(10), {{"growth", -1}}, &s), nullptr);
  EXPECT_EQ(r.Create("reference", McmcContext(10), {{"growth", 1}}, &s), nullptr);
  // The solver's options check the same, before any training.
  SolverOptions o;
  o.density = "mcmc";
  EXPECT_NE(o.Validate().message().find("--density: density strategy \"mcmc\": needs a budget"),
            std::string::npos)
      << o.Validate().message();
  o.max_gaussians = o.max_surfels = 1000;
  EXPECT_TRUE(o.Validate().ok()) << o.Validate().message();
}

TEST(DensityStrategyTest, MomentMatchingKeepsTheCompositeOpacityAndMatchesHandValues) {
  // One copy: unchanged.
  const Relocation one = MomentMatchedRelocation(0.7, 1);
  EXPECT_NEAR(one.opacity, 0.7, 1e-12);
  EXPECT_NEAR(one.scale_factor, 1.0, 1e-12);
  // N copies composite to the original opacity: 1 - (1 - o')^N = o.
  for (int n : {2, 3, 7, 51}) {
    const Relocation r = MomentMatchedRelocation(0.6, n);
    EXPECT_NEAR(1 - std::pow(1 - r.opacity, n), 0.6, 1e-9) << n;
  }
  // N = 2, o = 0.5 by hand: o' = 1 - sqrt(0.5); denominator = 2 o' - o'^2 / sqrt(2).
  const double o2 = 1 - std::sqrt(0.5);
  const Relocation two = MomentMatchedRelocation(0.5, 2);
  EXPECT_NEAR(two.opacity, o2, 1e-12);
  EXPECT_NEAR(two.scale_factor, 0.5 / (2 * o2 - o2 * o2 / std::sqrt(2.0)), 1e-12);
}

// Alpha of a model seen head-on from distance 3 (48 x 48 px): what relocation must not change.
const Camera& HeadOnCamera() {
  static const Camera camera =
      LookAtCamera({0, 0, 3}, {0, 0, 0}, Eigen::Vector3d::UnitY(), 48, 48, 60, 60);
  return camera;
}
template <class Renderer, class Render, class Model, class Options>
Image RenderAlpha(const Model& m, Options o) {
  o.camera = HeadOnCamera();
  o.sh_degree = 0;
  Renderer renderer;
  Render out;
  renderer.Forward(m, o, &out);
  return out.alpha;
}
Image AlphaOf(const GaussianModel& m) {
  GaussianRenderOptions o;
  o.reflection = false;
  return RenderAlpha<GaussianRenderer, GaussianRender>(m, o);
}
Image AlphaOf(const SurfelModel& m) {
  SurfelRenderOptions o;
  o.low_pass = SurfelLowPass::kAreaPreserving;
  o.filter_sigma = 0.29f;
  o.distortion = false;
  return RenderAlpha<SurfelRenderer, SurfelRender>(m, o);
}
double MaxAbsDiff(const Image& a, const Image& b) {
  double d = 0;
  for (size_t i = 0; i < a.size(); ++i)
    d = std::max(d, std::abs(static_cast<double>(a.data()[i]) - b.data()[i]));
  return d;
}
double Sum(const Image& a) {
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += a.data()[i];
  return s;
}

// Two rows of either type: row 0 a live primitive at the origin facing the camera (opacity `o`,
// scale 0.25), row 1 dead (opacity 1e-5, invisible) elsewhere.
template <class Model>
Model LiveAndDead(double o, int axes) {
  Model m;
  m.max_sh_degree = 0;
  m.Resize(2);
  for (int i = 0; i < 2; ++i) {
    m.quats[4 * i] = 1.0f;  // a surfel's normal is its z axis: towards the camera
    for (int k = 0; k < axes; ++k) m.log_scales[axes * i + k] = std::log(0.25f);
  }
  m.opacity_logits[0] = static_cast<float>(std::log(o / (1 - o)));
  m.opacity_logits[1] = std::log(1e-5f);  // opacity ~1e-5
  m.means[3 * 1] = 0.7f;
  if constexpr (std::is_same_v<Model, GaussianModel>) {
    m.ref_opacity_logits.assign(2, -30.0f);  // no reflected layer (MCMC judges by the larger)
  }
  return m;
}

// MCMC relocation keeps the rendered image to first order: N copies at the matched opacity and
// scale composite to the original alpha at the centre, and their footprint (the alpha image's sum)
// matches the original's, for 3D Gaussians and surfels alike. Copies that kept the original
// scale (opacity matched only) or the original opacity miss both by several times more.
template <class Model, class Primitive>
void ExpectRelocationKeepsTheImage(int axes) {
  for (double o : {0.3, 0.6, 0.9}) {
    SCOPED_TRACE(o);
    Adam adam;
    Model m = LiveAndDead<Model>(o, axes);
    const Image before = AlphaOf(m);
    ASSERT_GT(Sum(before), 20.0);
    const PrimitiveLayout layout = Primitive::Layout();
    PrimitiveRows rows(m.Blocks(), &adam, &layout);
    McmcDensity mcmc = RelocatingMcmc(2);
    Rng rng(1);
    ASSERT_EQ(mcmc.AfterStep(EventStep(10), &rows, &rng).relocated, 1u);
    ASSERT_EQ(m.means[3 * 1], 0.0f) << "the dead row now sits on the live one";
    const Image after = AlphaOf(m);
    // Controls: opacity matched but the scale kept; a plain copy.
    Model scale_kept = m, plain = LiveAndDead<Model>(o, axes);
    for (int k = 0; k < axes; ++k)
      for (int i = 0; i < 2; ++i) scale_kept.log_scales[axes * i + k] = std::log(0.25f);
    plain.means[3 * 1] = 0.0f;
    plain.opacity_logits[1] = plain.opacity_logits[0];
    const Image kept = AlphaOf(scale_kept), copied = AlphaOf(plain);
    const int centre = 24 * 48 + 24;
    // The centre: the copies composite to the original alpha (a plain copy's is o (1 - o) more).
    EXPECT_NEAR(after.data()[centre], before.data()[centre], 0.005);
    EXPECT_GT(std::abs(copied.data()[centre] - before.data()[centre]), 0.5 * o * (1 - o));
    // The footprint: within 6% (measured 2.0-5.1%), nearer than with the scale kept (3-26% off)
    // and far nearer than a plain copy's (55-85%); no pixel off by more than 0.05 (0.008-0.041).
    const double footprint = std::abs(Sum(after) / Sum(before) - 1);
    EXPECT_LT(footprint, 0.06);
    EXPECT_LT(footprint, std::abs(Sum(kept) / Sum(before) - 1));
    EXPECT_GT(std::abs(Sum(copied) / Sum(before) - 1), 0.5);
    EXPECT_LT(MaxAbsDiff(after, before), 0.05);
  }
}

TEST(DensityStrategyTest, McmcRelocationKeepsTheRenderedImageToFirstOrder) {
  ExpectRelocationKeepsTheImage<GaussianModel, GaussianPrimitive>(3);
  ExpectRelocationKeepsTheImage<SurfelModel, SurfelPrimitive>(2);
}

TEST(DensityStrategyTest, McmcRelocatesTheDeadOntoLivePrimitivesAndZeroesTheirMoments) {
  Adam adam;
  GaussianModel m = LineOfGaussians(6, &adam);
  m.opacity_logits[1] = m.opacity_logits[4] = -10.0f;  // dead
  m.ref_opacity_logits[1] = m.ref_opacity_logits[4] = -10.0f;
  m.ref_opacity_logits[5] = 3.0f;  // transparent but reflecting: alive
  m.opacity_logits[5] = -10.0f;
  const PrimitiveLayout layout = GaussianPrimitive::Layout();
  PrimitiveRows rows(m.Blocks(), &adam, &layout);
  McmcDensity mcmc = RelocatingMcmc(6);
  Rng rng(3);
  const DensifyResult r = mcmc.AfterStep(EventStep(10), &rows, &rng);
  EXPECT_EQ(r.relocated, 2u);
  EXPECT_EQ(r.added, 0u);
  ASSERT_EQ(m.size(), 6u);
  // Each former dead row is now a copy of a live row (its colour says which), and shares that
  // row's matched opacity, below the original 0.5.
  for (int dead : {1, 4}) {
    const int source = static_cast<int>(m.sh[3 * dead]);
    EXPECT_NE(source, 1);
    EXPECT_NE(source, 4);
    EXPECT_EQ(m.means[3 * dead], m.means[3 * source]);
    EXPECT_EQ(m.opacity_logits[dead], m.opacity_logits[source]);
    if (source != 5) {
      EXPECT_LT(Sigmoid(m.opacity_logits[dead]), 0.5f);
    } else {
      EXPECT_LT(Sigmoid(m.opacity_logits[dead]), 1e-3f) << "reflecting only";
    }
    for (const char* block : {"means", "opacity_logits", "sh"}) {
      const Adam::BlockState& s = adam.state().at(block);
      for (int row : {dead, source}) EXPECT_EQ(s.m[s.width * row], 0.0f) << block << " " << row;
    }
  }
  // Untouched rows keep their moments.
  std::set<int> touched = {1, 4, static_cast<int>(m.sh[3]), static_cast<int>(m.sh[12])};
  for (int i = 0; i < 6; ++i) {
    if (touched.count(i) == 0) {
      EXPECT_NE(adam.state().at("means").m[3 * i], 0.0f) << i;
    }
  }
  // No event outside the schedule's iterations.
  EXPECT_EQ(mcmc.AfterStep(EventStep(11), &rows, &rng).relocated, 0u);
}

TEST(DensityStrategyTest, McmcGrowsByItsRateAndNeverPastTheCap) {
  Adam adam;
  GaussianModel m = LineOfGaussians(40, &adam);
  const PrimitiveLayout layout = GaussianPrimitive::Layout();
  PrimitiveRows rows(m.Blocks(), &adam, &layout);
  McmcOptions mo;
  mo.growth = 0.1f;
  McmcDensity mcmc(McmcContext(50), mo);
  Rng rng(5);
  EXPECT_EQ(mcmc.AfterStep(EventStep(10), &rows, &rng).added, 4u);  // floor(1.1 x 40) - 40
  EXPECT_EQ(m.size(), 44u);
  for (const auto& [name, s] : adam.state()) EXPECT_EQ(s.m.size(), m.size() * s.width) << name;
  for (int it = 20; it < 200; it += 10) mcmc.AfterStep(EventStep(it), &rows, &rng);
  EXPECT_EQ(m.size(), 50u);
  // With few events (the fast preset's 2DGS schedule: 9), Begin raises the rate so the cap is
  // reached by half of them: 1,000 -> 4,000 at 1.414 per event, four events.
  Adam adam3;
  GaussianModel few = LineOfGaussians(1000, &adam3);
  PrimitiveRows few_rows(few.Blocks(), &adam3, &layout);
  DensityContext fast = McmcContext(4000);
  fast.schedule = {100, 1000, 100, 100000, 0.005f};
  McmcDensity quick(fast, McmcOptions());
  quick.Begin(&few_rows, &rng);
  EXPECT_NEAR(quick.growth(), std::sqrt(2.0) - 1, 1e-4);
  for (int it = 200; it <= 500; it += 100) quick.AfterStep(EventStep(it), &few_rows, &rng);
  EXPECT_GE(few.size(), 3990u);
  quick.AfterStep(EventStep(600), &few_rows, &rng);
  EXPECT_EQ(few.size(), 4000u);
  // Begin trims a model above the cap to a subset of its rows.
  Adam adam2;
  GaussianModel big = LineOfGaussians(80, &adam2);
  PrimitiveRows big_rows(big.Blocks(), &adam2, &layout);
  mcmc.Begin(&big_rows, &rng);
  ASSERT_EQ(big.size(), 50u);
  std::set<float> distinct(big.means.begin(), big.means.end());
  EXPECT_GE(distinct.size(), 50u);  // 50 different x positions (plus 0 for y, z)
}

// The regulariser's gradient against central differences in double precision of its value.
TEST(DensityStrategyTest, McmcRegulariserGradientMatchesNumericDifferentiation) {
  for (const bool surfels : {false, true}) {
    SCOPED_TRACE(surfels ? "surfels" : "gaussians");
    Adam adam;
    GaussianModel m = LineOfGaussians(5, &adam);
    SurfelModel sm;
    const PrimitiveLayout layout =
        surfels ? SurfelPrimitive::Layout() : GaussianPrimitive::Layout();
    if (surfels) {
      sm.max_sh_degree = 0;
      sm.Resize(5);
      for (int i = 0; i < 5; ++i) sm.quats[4 * i] = 1;
    }
    for (size_t i = 0; i < 5; ++i) {
      (surfels ? sm.opacity_logits : m.opacity_logits)[i] = -1.0f + 0.5f * i;
      for (int k = 0; k < layout.scale_axes; ++k)
        (surfels ? sm.log_scales : m.log_scales)[layout.scale_axes * i + k] =
            -3.0f + 0.3f * k + 0.1f * i;
    }
    std::vector<ParamBlock> blocks = surfels ? sm.Blocks() : m.Blocks();
    PrimitiveRows rows(blocks, &adam, &layout);
    DensityContext c = McmcContext(10);
    c.extent = 2.5;
    McmcOptions mo;
    mo.opacity_reg = 0.3f;
    mo.scale_reg = 0.7f;
    McmcDensity mcmc(c, mo);
    auto value_and_gradient = [&](std::vector<float>* d_opacity, std::vector<float>* d_scale) {
      GaussianModel gm;
      SurfelModel gs;
      std::vector<ParamBlock> g;
      if (surfels) {
        gs.max_sh_degree = 0;
        gs.Resize(5);
        g = gs.Blocks();
      } else {
        gm.max_sh_degree = 0;
        gm.Resize(5);
        g = gm.Blocks();
      }
      for (ParamBlock& b : g) std::fill(b.data->begin(), b.data->end(), 0.0f);
      const double v = mcmc.BeforeStep(EventStep(1), rows, g);
      for (ParamBlock& b : g) {
        if (b.name == "opacity_logits" && d_opacity) *d_opacity = *b.data;
        if (b.name == "log_scales" && d_scale) *d_scale = *b.data;
      }
      return v;
    };
    std::vector<float> d_opacity, d_scale;
    value_and_gradient(&d_opacity, &d_scale);
    for (const char* name : {"opacity_logits", "log_scales"}) {
      float* x = rows.Block(name);
      const std::vector<float>& analytic =
          std::string(name) == "opacity_logits" ? d_opacity : d_scale;
      for (size_t j = 0; j < analytic.size(); ++j) {
        const float saved = x[j];
        const double h = 1e-2;
        x[j] = static_cast<float>(saved + h);
        const double plus = value_and_gradient(nullptr, nullptr);
        x[j] = static_cast<float>(saved - h);
        const double minus = value_and_gradient(nullptr, nullptr);
        x[j] = saved;
        const double numeric = (plus - minus) / (2 * h);
        EXPECT_NEAR(analytic[j], numeric, 1e-3 * std::abs(numeric) + 1e-7) << name << " " << j;
        EXPECT_GT(analytic[j], 0.0f) << "pulls opacity and scale down";
      }
    }
  }
}

TEST(DensityStrategyTest, McmcNoiseMovesOnlyTransparentPrimitivesAndKeepsSurfelsInTheirPlane) {
  SurfelModel m;
  m.max_sh_degree = 0;
  m.Resize(2);
  // Both disks tilted 40 degrees about x; the first opaque, the second almost transparent.
  const float half = 0.5f * 40.0f * 3.14159265f / 180.0f;
  for (int i = 0; i < 2; ++i) {
    m.quats[4 * i] = std::cos(half);
    m.quats[4 * i + 1] = std::sin(half);
    m.log_scales[2 * i] = std::log(0.2f);
    m.log_scales[2 * i + 1] = std::log(0.1f);
  }
  m.opacity_logits[0] = InverseSigmoid(0.9f);
  m.opacity_logits[1] = InverseSigmoid(0.002f);
  Adam adam;
  const PrimitiveLayout layout = SurfelPrimitive::Layout();
  PrimitiveRows rows(m.Blocks(), &adam, &layout);
  McmcOptions noisy;
  noisy.noise_lr = 5e5f;  // gsplat's (the default is off)
  McmcDensity mcmc(McmcContext(2), noisy);
  Rng rng(11);
  DensityStep step = EventStep(15);  // not an event: noise only
  step.position_lr = 1.6e-4f;
  const std::vector<float> before = m.means;
  mcmc.AfterStep(step, &rows, &rng);
  for (int r = 0; r < 3; ++r) EXPECT_EQ(m.means[r], before[r]) << "opaque disks stay";
  float R[9], q[4];
  QuaternionToRotation(&m.quats[4], R, q);
  double moved = 0, along_normal = 0;
  for (int r = 0; r < 3; ++r) {
    const double d = m.means[3 + r] - before[3 + r];
    moved += d * d;
    along_normal += d * R[3 * r + 2];  // third column: the disk's normal
  }
  EXPECT_GT(std::sqrt(moved), 1e-4);
  EXPECT_LT(std::abs(along_normal), 1e-6 + 1e-3 * std::sqrt(moved));
}

TEST(DensityStrategyTest, AutoBudgetCountsTheForegroundOfTheMedianView) {
  Scene scene;
  for (int i = 0; i < 3; ++i) {
    View v;
    v.camera.width = 100;
    v.camera.height = 80;
    v.mask = Image(100, 80, 1);
    // 2,000 / 4,000 / 6,000 foreground pixels: the median is 4,000.
    for (int y = 0; y < 20 * (i + 1); ++y)
      for (int x = 0; x < 100; ++x) v.mask.at(0, y, x) = 1.0f;
    scene.views.push_back(std::move(v));
  }
  SceneBudget b = AutoPrimitiveBudget(scene);
  EXPECT_EQ(b.foreground_pixels, 4000);
  // 180 and 135 x sqrt(4000) = 11,384 and 8,538.
  EXPECT_EQ(b.gaussians, 11384u);
  EXPECT_EQ(b.surfels, 8538u);
  EXPECT_NE(b.why.find("4000 by mask"), std::string::npos) << b.why;
  // Without masks or alpha every pixel counts.
  for (View& v : scene.views) v.mask = Image();
  b = AutoPrimitiveBudget(scene);
  EXPECT_EQ(b.foreground_pixels, 8000);
  EXPECT_NE(b.why.find("every pixel"), std::string::npos) << b.why;
}

// Pruning by contribution drops what no training view sees (behind every camera, hidden behind
// an opaque Gaussian) and keeps what renders, with the optimiser state.
TEST(DensityStrategyTest, PruningByContributionDropsWhatNoViewShows) {
  GaussianModel m;
  m.max_sh_degree = 0;
  m.Resize(3);
  for (int i = 0; i < 3; ++i) {
    m.quats[4 * i] = 1;
    for (int k = 0; k < 3; ++k) m.log_scales[3 * i + k] = std::log(0.3f);
    m.opacity_logits[i] = 8.0f;        // opaque
    m.ref_opacity_logits[i] = -30.0f;  // no reflected layer
  }
  m.means[3 * 1 + 1] = -9.0f;  // 1: behind the camera
  m.means[3 * 2 + 1] = 1.0f;   // 2: right behind 0, small and hidden
  for (int k = 0; k < 3; ++k) m.log_scales[3 * 2 + k] = std::log(0.05f);
  const Camera camera =
      LookAtCamera({0, -3, 0}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), 32, 32, 40, 40);
  ExposureModel exposure;
  exposure.Reset(1, ExposureMode::kOff);
  Rng rng(1);
  BranchTrainerOptions bo;
  GaussianRenderOptions ro;
  ro.reflection = false;
  GaussianTrainer t(m, ro, bo, &exposure, &rng);
  EXPECT_EQ(t.PruneByContribution({camera}, 1.0), 2u);
  ASSERT_EQ(t.size(), 1u);
  EXPECT_EQ(t.model().means[1], 0.0f);
  EXPECT_EQ(t.summary().pruned_by_contribution, 2u);
  // Never everything.
  EXPECT_EQ(t.PruneByContribution({camera}, 1e9), 0u);
  EXPECT_EQ(t.size(), 1u);
}

TEST(DensityStrategyTest, AnMcmcSolveKeepsEachBranchWithinItsBudgetAndTrains) {
  const Scene scene = testing::TinySolverScene(testing::ScratchDir());
  ASSERT_FALSE(scene.views.empty());
  SolverOptions o;
  SolverOptions::FromPreset("fast", &o);
  o.warmup_min_iterations = 0;
  o.warmup_max_iterations = 100;
  o.mutual_iterations = 20;
  o.auto_stop = false;
  o.schedule_2d = {10, 90, 10, 1000, 0.05f};
  o.schedule_3d = {10, 90, 10, 1000, 0.005f};
  o.density = "mcmc";
  o.density_config = {{"growth", 0.5}};  // reaches the caps within the few events of this run
  o.max_gaussians = 300;
  o.max_surfels = 200;
  MutualBoostedSolver solver(o, scene);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  EXPECT_EQ(summary.branch(Branch::kGaussians3D).primitives, 300u);
  EXPECT_EQ(summary.branch(Branch::kSurfels2D).primitives, 200u);
  EXPECT_EQ(summary.branch(Branch::kGaussians3D).pruned_by_contribution, 0u);
  EXPECT_TRUE(std::isfinite(summary.branch(Branch::kGaussians3D).final_loss));
}

}  // namespace
}  // namespace mgsr
