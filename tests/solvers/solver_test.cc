#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>

#include "mean_alpha_loss.h"
#include "mgsr/core/rng.h"
#include "mgsr/core/sha256.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/scene.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/loss/loss_util.h"
#include "mgsr/model/activations.h"
#include "same_models.h"
#include "short_run.h"
#include "solvers/adam.h"
#include "solvers/auto_stop.h"
#include "solvers/checkpoint_callback.h"
#include "solvers/density_control.h"
#include "solvers/density_strategy.h"
#include "solvers/exposure_fit.h"
#include "solvers/loss_table.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/primitive_types.h"
#include "test_util.h"

namespace mgsr {
namespace {

TEST(AdamTest, FirstStepsMatchTheFormula) {
  std::vector<float> x = {1.0f, -2.0f, 0.5f, 3.0f}, g = {0.5f, -1.0f, 0.0f, 2.0f};
  Adam adam;
  const std::vector<ParamBlock> p = {{"b", &x, 2}}, gr = {{"b", &g, 2}};
  auto rates = [](const std::string&, int width, std::vector<float>* r) {
    (*r)[0] = 0.1f;
    if (width > 1) (*r)[1] = 0.01f;  // per-column rates
  };
  adam.Step(p, gr, rates);
  // Step 1: m_hat = g, v_hat = g^2, so x -= lr * sign(g) (g != 0).
  EXPECT_NEAR(x[0], 1.0f - 0.1f, 1e-6f);
  EXPECT_NEAR(x[1], -2.0f + 0.01f, 1e-6f);
  EXPECT_NEAR(x[2], 0.5f, 1e-6f);
  EXPECT_NEAR(x[3], 3.0f - 0.01f, 1e-6f);
  adam.Step(p, gr, rates);  // same gradient again: the same step
  EXPECT_NEAR(x[0], 1.0f - 0.2f, 1e-5f);
  // Rows follow density control: keep row 1, add a zero row.
  adam.KeepRows({0, 1});
  adam.AppendZeroRows(1);
  EXPECT_EQ(adam.state().at("b").m.size(), 4u);
  EXPECT_EQ(adam.state().at("b").m[2], 0.0f);
  EXPECT_EQ(adam.state().at("b").m[0], 0.0f);  // kept row 1: its first column had zero gradient
  EXPECT_NE(adam.state().at("b").m[1], 0.0f);
}

TEST(AdamTest, IdleMomentsReachZeroInsteadOfTurningSubnormal) {
  // One step with a gradient, then a thousand without (a primitive no view sees any more): a
  // plain update leaves m at the smallest subnormal for ever (slow arithmetic on every step).
  std::vector<float> x(64, 1.0f), g(64, 1e-3f);
  Adam adam;
  const std::vector<ParamBlock> p = {{"b", &x, 4}}, gr = {{"b", &g, 4}};
  auto rates = [](const std::string&, int width, std::vector<float>* r) {
    for (int c = 0; c < width; ++c) (*r)[c] = 0.01f;
  };
  adam.Step(p, gr, rates);
  std::fill(g.begin(), g.end(), 0.0f);
  const float before = x[0];
  for (int i = 0; i < 1000; ++i) {
    adam.Step(p, gr, rates);
    for (float m : adam.state().at("b").m) ASSERT_NE(std::fpclassify(m), FP_SUBNORMAL) << i;
    for (float v : adam.state().at("b").v) ASSERT_NE(std::fpclassify(v), FP_SUBNORMAL) << i;
  }
  for (float m : adam.state().at("b").m) EXPECT_EQ(m, 0.0f);
  // The idle steps still moved x as exact Adam does (its decaying first moment): the flush
  // changes nothing measurable. Exact: m_k = 0.1 g 0.9^(k-1), v_k = 0.001 g^2 0.999^(k-1).
  double expected = 0;
  for (int k = 2; k <= 1001; ++k) {
    const double m = 0.1 * 1e-3 * std::pow(0.9, k - 1) / (1 - std::pow(0.9, k));
    const double v = 0.001 * 1e-6 * std::pow(0.999, k - 1) / (1 - std::pow(0.999, k));
    expected += 0.01 * m / (std::sqrt(v) + 1e-15);
  }
  EXPECT_NEAR(before - x[0], expected, 1e-5);
}

TEST(AutoStopTest, FiresOnAFlatWindowNotOnAFallingOne) {
  AutoStop flat(10, 20, 0.01);
  bool fired = false;
  int at = 0;
  for (int it = 1; it <= 100 && !fired; ++it) {
    fired = flat.Update(it, 0.5 + 0.001 * std::sin(it));
    at = it;
  }
  EXPECT_TRUE(fired);
  EXPECT_EQ(at, 30);  // not before the minimum iteration plus a full window
  AutoStop falling(10, 20, 0.01);
  for (int it = 1; it <= 200; ++it) EXPECT_FALSE(falling.Update(it, 1.0 - 0.002 * it)) << it;
}

TEST(DensityControlTest, ClonesSplitsPrunesAndKeepsTheBudget) {
  GaussianModel m;
  m.Resize(4);
  std::fill(m.sh.begin(), m.sh.end(), 0.0f);
  for (int i = 0; i < 4; ++i) {
    m.means[3 * i] = static_cast<float>(i);
    m.quats[4 * i] = 1.0f;
    m.opacity_logits[i] = 0.0f;
  }
  for (int k = 0; k < 3; ++k) {
    m.log_scales[k] = std::log(0.001f);      // 0: small, high gradient -> clone
    m.log_scales[3 + k] = std::log(0.5f);    // 1: large, high gradient -> split
    m.log_scales[6 + k] = std::log(0.001f);  // 2: low gradient -> untouched
    m.log_scales[9 + k] = std::log(0.001f);  // 3: transparent -> pruned
  }
  m.opacity_logits[3] = -10.0f;
  Adam adam;
  GaussianGradients g;
  g.ResizeAndZero(m);
  adam.Step(m.Blocks(), g.params.Blocks(),
            [](const std::string&, int, std::vector<float>* r) { r->assign(r->size(), 0.1f); });
  DensityStats stats;
  stats.Reset(4);
  stats.AccumulateViews({1e-3f, 1, 1e-3f, 1, 1e-6f, 1, 1e-6f, 1});  // (norm, drawn) per primitive
  DensityOptions o;
  Rng rng(1);
  const PrimitiveLayout layout = GaussianPrimitive::Layout();
  PrimitiveRows rows(m.Blocks(), &adam, &layout);
  const DensifyResult r = DensifyAndPrune(&rows, &stats, o, /*extent=*/1.0, false, &rng);
  EXPECT_EQ(r.cloned, 1u);
  EXPECT_EQ(r.split, 1u);
  EXPECT_EQ(r.pruned, 1u);
  EXPECT_EQ(m.size(), 4u + 1 + 2 - 1 - 1);  // + clone + 2 children - parent - pruned
  for (const auto& [name, s] : adam.state()) EXPECT_EQ(s.m.size(), m.size() * s.width) << name;
  // Children are smaller than their parent by 1.6.
  EXPECT_NEAR(std::exp(m.log_scales[3 * (m.size() - 1)]), 0.5f / 1.6f, 1e-5f);
  // A budget caps the growth.
  stats.Reset(m.size());
  std::vector<float> high(2 * m.size(), 1.0f);
  for (size_t i = 0; i < m.size(); ++i) high[2 * i] = 1e-3f;
  stats.AccumulateViews(high);
  o.max_primitives = m.size() + 1;
  DensifyAndPrune(&rows, &stats, o, 1.0, false, &rng);
  EXPECT_LE(m.size(), o.max_primitives);
  // Opacity reset caps opacity, reflected opacity and beta, and zeroes their moments.
  rows.ResetOpacity();
  for (size_t i = 0; i < m.size(); ++i) {
    EXPECT_LE(Sigmoid(m.opacity_logits[i]), 0.0100001f);
    EXPECT_LE(Sigmoid(m.ref_opacity_logits[i]), 0.0100001f);
    EXPECT_LE(Sigmoid(m.beta_logits[i]), 0.100001f);
  }
  for (const char* block : {"opacity_logits", "ref_opacity_logits", "beta_logits"}) {
    for (float v : adam.state().at(block).m) EXPECT_EQ(v, 0.0f) << block;
  }
}

class Recorder : public IterationCallback {
 public:
  CallbackReturnType operator()(const IterationInfo& i) override {
    calls.push_back(i);
    return CallbackReturnType::kContinue;
  }
  std::vector<IterationInfo> calls;
};

SolverOptions TinyOptions() {
  SolverOptions o = testing::ShortFastOptions(120, 20);
  o.schedule_2d = {20, 100, 20, 1000, 0.05f};
  o.schedule_3d = {20, 100, 10, 1000, 0.005f};
  o.sh_interval = 40;
  return o;
}

Scene TinyScene(const std::string& dir) { return testing::TinySolverScene(dir); }

double TestPsnr(MutualBoostedSolver* solver, const Scene& scene) {
  double psnr = 0;
  for (int i : scene.TestIndices()) {
    GaussianRender r;
    solver->RenderGaussians(scene.views[i].camera, &r);
    const Image gt = CompositeOnBackground(scene.views[i], 0.0f);
    psnr += Psnr(r.color, gt);
  }
  return psnr / scene.TestIndices().size();
}

TEST(MutualBoostedSolverTest, EndToEndLossFallsAndPsnrRises) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  MutualBoostedSolver solver(o, scene);
  const double psnr_before = TestPsnr(&solver, scene);
  Recorder rec;
  solver.AddCallback(&rec);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  const double psnr_after = TestPsnr(&solver, scene);
  // Mean 3DGS loss over the first and the last 20 warm-up iterations.
  double first = 0, last = 0;
  int nf = 0, nl = 0;
  for (const IterationInfo& i : rec.calls) {
    if (i.stage != Stage::kWarmup || i.branch != Branch::kGaussians3D) continue;
    if (i.iteration <= 20) first += i.loss, ++nf;
    if (i.iteration > 100) last += i.loss, ++nl;
  }
  EXPECT_LT(last / nl, 0.7 * first / nf);
  EXPECT_GT(psnr_after, psnr_before + 3) << psnr_before << " -> " << psnr_after;
  EXPECT_EQ(summary.branch(Branch::kSurfels2D).warmup_iterations, 120);
  EXPECT_EQ(summary.mutual_iterations, 20);
}

// The density strategy is handed the means' learning rate of the step (what MCMC scales its
// position noise by). It was 0 for every run of mgsr_solve until the fix: the solver's rate
// function fills the list it is given, and the trainer gave it an empty one.
struct PositionRateProbe : DensityStrategy {
  static std::vector<float> seen;
  void Begin(PrimitiveRows*, Rng*) override {}
  double BeforeStep(const DensityStep& step, const PrimitiveRows&,
                    const std::vector<ParamBlock>&) override {
    seen.push_back(step.position_lr);
    return 0;
  }
  DensifyResult AfterStep(const DensityStep&, PrimitiveRows*, Rng*) override { return {}; }
  void Save(BinaryWriter*) const override {}
  Status Read(BinaryReader*) override { return Status::Ok(); }
  void CommitRead() override {}
};
std::vector<float> PositionRateProbe::seen;

TEST(MutualBoostedSolverTest, DensityStrategiesSeeTheStepsPositionRate) {
  DensityStrategyRegistry::Get().Register("position_rate_probe",
                                          [](const DensityContext&, const nlohmann::json&,
                                             Status*) -> std::unique_ptr<DensityStrategy> {
                                            return std::make_unique<PositionRateProbe>();
                                          });
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 10;
  o.mutual_iterations = 0;
  o.density = "position_rate_probe";
  ASSERT_TRUE(o.Validate().ok());
  PositionRateProbe::seen.clear();
  MutualBoostedSolver solver(o, scene);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  ASSERT_EQ(PositionRateProbe::seen.size(), 20u);  // both branches, 10 steps each
  // The log-linear schedule from position_lr_init x extent, 10 steps into position_lr_max_steps.
  const double at_step_10 =
      0.99 * o.position_lr_init * scene.extent *
      std::pow(o.position_lr_final / o.position_lr_init, 10.0 / o.position_lr_max_steps);
  for (float lr : PositionRateProbe::seen) {
    EXPECT_GT(lr, at_step_10);
    EXPECT_LE(lr, 1.0001 * o.position_lr_init * scene.extent);
  }
  // The 2DGS branch's own decay: over its 10 steps here, while the 3DGS branch keeps
  // position_lr_max_steps. The branches step in turn, 2DGS first.
  o.position_lr_max_steps_2d = 10;
  PositionRateProbe::seen.clear();
  MutualBoostedSolver own_decay(o, scene);
  ASSERT_TRUE(own_decay.Solve(&summary).ok());
  ASSERT_EQ(PositionRateProbe::seen.size(), 20u);
  EXPECT_NEAR(PositionRateProbe::seen[18], o.position_lr_final * scene.extent,
              1e-4 * o.position_lr_final * scene.extent);
  EXPECT_GT(PositionRateProbe::seen[19], at_step_10);
  EXPECT_LT(PositionRateProbe::seen[2], PositionRateProbe::seen[3]);
}

TEST(MutualBoostedSolverTest, ProfileAccountsForEachStage) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 30;
  o.mutual_iterations = 10;
  MutualBoostedSolver solver(o, scene);
  SolveSummary summary;
  Profiler::SetEnabled(true);
  const Status s = solver.Solve(&summary);
  Profiler::SetEnabled(false);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(summary.profile.size(), 2u);
  const StageProfile& warmup = summary.profile[0];
  const StageProfile& mutual = summary.profile[1];
  EXPECT_EQ(warmup.stage, Stage::kWarmup);
  EXPECT_EQ(warmup.iterations, 30);
  EXPECT_EQ(mutual.stage, Stage::kMutual);
  EXPECT_EQ(mutual.iterations, 10);
  for (const StageProfile& p : summary.profile) {
    std::map<std::string, int64_t> calls;
    double named = 0;
    for (const ProfileEntry& e : p.entries) {
      calls[e.context + "/" + e.name] += e.calls;
      named += e.seconds;
    }
    // Exclusive times never add up to more than the stage's wall time.
    EXPECT_LE(named, p.seconds * 1.001 + 1e-4);
    if (p.stage == Stage::kWarmup) {
      // Both branches step every warm-up iteration.
      EXPECT_EQ(calls["2DGS/raster forward"], 30);
      EXPECT_EQ(calls["3DGS/raster backward"], 30);
      EXPECT_EQ(calls["3DGS/loss: photo"], 30);
      EXPECT_EQ(calls["2DGS/adam"], 30);
      // The callbacks, the caller's work: after each branch's step and at the iteration's end.
      EXPECT_EQ(calls["/callbacks"], 30 * 3);
    } else {
      // Alternate: each branch learns on every other iteration and supervises on the others.
      // A round (2DGS step, 3DGS step) takes one view, and each branch renders it once: the
      // 3DGS step reuses its render that supervised the 2DGS step (the branch has not changed
      // since), and its depth target is the 2DGS step's render.
      EXPECT_EQ(calls["2DGS/raster backward"], 5);
      EXPECT_EQ(calls["2DGS/raster forward"], 5);
      EXPECT_EQ(calls["3DGS/raster backward"], 5);
      EXPECT_EQ(calls["3DGS/raster forward"], 5);
      EXPECT_EQ(calls["/mutual targets"], 10);
      EXPECT_EQ(calls["/exposure fit"], 1);
      EXPECT_EQ(calls["/callbacks"], 10 * 2);
    }
  }
  // Off again: the next solve records nothing.
  MutualBoostedSolver quiet(o, scene);
  ASSERT_TRUE(quiet.Solve(&summary).ok());
  EXPECT_TRUE(summary.profile.empty());
}

TEST(MutualBoostedSolverTest, AlternateAndJointCallOrder) {
  const Scene scene = TinyScene(testing::ScratchDir());
  for (const char* mode : {"alternate", "joint"}) {
    SolverOptions o = TinyOptions();
    o.warmup_max_iterations = 4;
    o.mutual_iterations = 6;
    o.mutual_mode = mode;
    MutualBoostedSolver solver(o, scene);
    Recorder rec;
    solver.AddCallback(&rec);
    SolveSummary summary;
    ASSERT_TRUE(solver.Solve(&summary).ok());
    std::string order;
    for (const IterationInfo& i : rec.calls) {
      if (i.stage == Stage::kMutual) order += i.branch == Branch::kSurfels2D ? "2" : "3";
    }
    // Warm-up interleaves the branches in both modes.
    ASSERT_GE(rec.calls.size(), 8u);
    EXPECT_EQ(rec.calls[0].branch, Branch::kSurfels2D);
    EXPECT_EQ(rec.calls[1].branch, Branch::kGaussians3D);
    if (std::string(mode) == "alternate") {
      EXPECT_EQ(order, "232323");
    } else {
      EXPECT_EQ(order, "232323232323");
    }
  }
}

// In alternate mode each branch steps every other iteration; density control and opacity resets
// fall on even counts, and must still reach the branch that steps on odd ones (the 2DGS branch).
TEST(MutualBoostedSolverTest, DensityControlReachesBothBranchesInEitherMode) {
  const Scene scene = TinyScene(testing::ScratchDir());
  for (const char* mode : {"alternate", "joint"}) {
    SCOPED_TRACE(mode);
    SolverOptions o = TinyOptions();
    o.warmup_max_iterations = 4;
    o.mutual_iterations = 9;
    o.mutual_mode = mode;
    o.schedule_2d = {2, 100, 4, 1000, 0.05f};
    o.schedule_3d = {2, 100, 4, 1000, 0.005f};
    o.densify_grad_threshold = 0;  // every visible primitive is cloned or split
    MutualBoostedSolver solver(o, scene);
    Recorder rec;
    solver.AddCallback(&rec);
    SolveSummary summary;
    ASSERT_TRUE(solver.Solve(&summary).ok());
    size_t first_2d = 0, last_2d = 0, first_3d = 0, last_3d = 0;
    for (const IterationInfo& i : rec.calls) {
      if (i.stage != Stage::kMutual) continue;
      if (i.branch == Branch::kSurfels2D) {
        if (first_2d == 0) first_2d = i.num_surfels;
        last_2d = i.num_surfels;
      } else {
        if (first_3d == 0) first_3d = i.num_gaussians;
        last_3d = i.num_gaussians;
      }
    }
    // Densification at 4 and 8 in both branches' schedules (from 2, every 4).
    EXPECT_GT(last_2d, first_2d);
    EXPECT_GT(last_3d, first_3d);
  }
}

// The harness's methods: one branch alone leaves the other untouched and skips the mutual stage;
// plain 3DGS keeps its reflected layer at zero.
TEST(MutualBoostedSolverTest, SingleBranchMethods) {
  const Scene scene = TinyScene(testing::ScratchDir());
  for (const char* method : {"2dgs", "3dgs", "3dgs-ref"}) {
    SCOPED_TRACE(method);
    SolverOptions o = TinyOptions();
    o.warmup_max_iterations = 40;
    o.mutual_iterations = 20;
    ASSERT_TRUE(SolverOptions::ApplyMethod(method, &o));
    EXPECT_EQ(o.warmup_max_iterations, 60);
    EXPECT_EQ(o.mutual_iterations, 0);
    MutualBoostedSolver solver(o, scene);
    const GaussianModel g0 = solver.gaussians();
    const SurfelModel s0 = solver.surfels();
    SolveSummary summary;
    ASSERT_TRUE(solver.Solve(&summary).ok());
    EXPECT_EQ(summary.mutual_iterations, 0);
    EXPECT_EQ(summary.branch(Branch::kSurfels2D).warmup_iterations, o.train_2d ? 60 : 0);
    EXPECT_EQ(summary.branch(Branch::kGaussians3D).warmup_iterations, o.train_3d ? 60 : 0);
    EXPECT_EQ(solver.gaussians().means == g0.means, !o.train_3d);
    EXPECT_EQ(solver.surfels().means == s0.means, !o.train_2d);
    if (std::string(method) == "3dgs") {
      for (float l : solver.gaussians().ref_opacity_logits) EXPECT_LT(Sigmoid(l), 1e-6f);
    }
    if (std::string(method) == "3dgs-ref") {
      EXPECT_NE(solver.gaussians().ref_sh, g0.ref_sh);
    }
  }
  SolverOptions o;
  EXPECT_FALSE(SolverOptions::ApplyMethod("nerf", &o));
}

// spread_initial_surfels: the 2DGS branch starts with its whole budget of disks, the 3DGS branch
// with one Gaussian per point either way; without a budget (0) nothing is spread.
TEST(MutualBoostedSolverTest, SpreadInitialSurfelsFillsTheTwoDBudgetOnly) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.max_surfels = 3 * scene.points.size() + 1;
  o.max_gaussians = 5 * scene.points.size();
  const MutualBoostedSolver one_each(o, scene);
  EXPECT_EQ(one_each.surfels().size(), scene.points.size());
  o.spread_initial_surfels = true;
  const MutualBoostedSolver spread(o, scene);
  EXPECT_EQ(spread.surfels().size(), o.max_surfels);
  EXPECT_EQ(spread.gaussians().size(), scene.points.size());
  EXPECT_EQ(spread.gaussians().means, one_each.gaussians().means);
  // Closer disks, smaller ones: the mean log scale falls by about log sqrt(3).
  const auto mean_log_scale = [](const SurfelModel& m) {
    double sum = 0;
    for (float v : m.log_scales) sum += v;
    return sum / m.log_scales.size();
  };
  EXPECT_LT(mean_log_scale(spread.surfels()), mean_log_scale(one_each.surfels()) - 0.3);
  o.max_surfels = 0;
  EXPECT_EQ(MutualBoostedSolver(o, scene).surfels().size(), scene.points.size());
}

TEST(MutualBoostedSolverTest, InvalidOptionsAreRejected) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.mutual_mode = "sometimes";
  MutualBoostedSolver solver(o, scene);
  SolveSummary summary;
  const Status s = solver.Solve(&summary);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("--mutual_mode must be alternate or joint"), std::string::npos);
  o = TinyOptions();
  o.background_3d = std::nanf("");
  EXPECT_EQ(o.Validate().message(), "background levels must be in [0, 1]");
  o = TinyOptions();
  o.position_lr_max_steps = 0;
  EXPECT_EQ(o.Validate().message(), "--position_lr_max_steps must be >= 1");
}

// `paper` keeps the reference's mutual stage but warms up and shapes the surface on fast's
// schedule: the warm-up's length, the 2DGS position rate's decay and the start of the normal and
// patch terms; the 3DGS branch keeps the reference's decay and both the reference's density
// schedules.
TEST(SolverOptionsTest, PaperShapesTheSurfaceOnFastsSchedule) {
  SolverOptions paper, fast;
  ASSERT_TRUE(SolverOptions::FromPreset("paper", &paper));
  ASSERT_TRUE(SolverOptions::FromPreset("fast", &fast));
  EXPECT_EQ(paper.mutual_iterations, 20000);
  EXPECT_EQ(fast.mutual_iterations, 1500);
  EXPECT_EQ(fast.position_lr_max_steps_2d, -1);  // as before the option: both branches alike
  EXPECT_EQ(paper.schedule_2d.densify_until, 15000);
  EXPECT_EQ(fast.schedule_2d.densify_until, 1000);
  for (const SolverOptions* o : {&paper, &fast}) {
    EXPECT_EQ(o->warmup_min_iterations, 1125);
    EXPECT_EQ(o->warmup_max_iterations, 1500);
    EXPECT_EQ(o->PositionDecaySteps(Branch::kSurfels2D), 2250);
    EXPECT_EQ(o->normal_from_iteration, 525);
    EXPECT_EQ(o->multiview_from_iteration, 525);
    EXPECT_TRUE(o->Validate().ok()) << o->Validate().message();
  }
  EXPECT_EQ(paper.PositionDecaySteps(Branch::kGaussians3D), 30000);
  EXPECT_EQ(fast.PositionDecaySteps(Branch::kGaussians3D), 2250);
  // The rows the loss table builds start where the options say.
  for (const LossSpec& row : paper.LossTable()) {
    if (row.branch == Branch::kSurfels2D && row.stage == Stage::kWarmup &&
        (row.name == "normal_consistency" || row.name == "normal_tv" ||
         row.name == "multiview_ncc")) {
      EXPECT_EQ(row.first_iteration, 526) << row.name;
    }
  }
  SolverOptions defaults;
  EXPECT_EQ(defaults.PositionDecaySteps(Branch::kSurfels2D), 30000);
  defaults.position_lr_max_steps_2d = 0;
  EXPECT_EQ(defaults.Validate().message(),
            "--position_lr_max_steps_2d must be >= 1 (or -1: --position_lr_max_steps)");
  SolverOptions unknown;
  EXPECT_FALSE(SolverOptions::FromPreset("slow", &unknown));
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

class StopAt : public IterationCallback {
 public:
  StopAt(MutualBoostedSolver* solver, Stage stage, int iteration)
      : solver_(solver), stage_(stage), iteration_(iteration) {}
  CallbackReturnType operator()(const IterationInfo& i) override {
    if (i.stage == stage_ && i.iteration == iteration_) solver_->RequestStop();
    return CallbackReturnType::kContinue;
  }

 private:
  MutualBoostedSolver* solver_;
  Stage stage_;
  int iteration_;
};

using testing::ExpectSameModels;

TEST(CheckpointTest, InterruptedAndResumedRunEqualsAnUninterruptedOne) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  struct Variant {
    ExposureMode exposure;
    const char* density;
    bool environment;
    double surfel_layer = 0;  // a prior row (stateless: nothing of it in the checkpoint)
  };
  for (const Variant& variant :
       {Variant{ExposureMode::kOff, "reference", false},
        Variant{ExposureMode::kAffine, "reference", false},
        Variant{ExposureMode::kOff, "mcmc", false}, Variant{ExposureMode::kAffine, "mcmc", true},
        Variant{ExposureMode::kAffine, "reference", false, 3.0}}) {
    const ExposureMode exposure = variant.exposure;
    SCOPED_TRACE(std::string(ExposureModeName(exposure)) + " " + variant.density +
                 (variant.environment ? " environment" : "") +
                 (variant.surfel_layer > 0 ? " surfel layer" : ""));
    SolverOptions o = TinyOptions();
    o.exposure = exposure;
    o.lambda_surfel_layer = variant.surfel_layer;
    o.density = variant.density;
    o.environment = variant.environment;
    o.max_gaussians = 400;  // MCMC's caps (the reference stays below them here)
    o.max_surfels = 300;
    o.warmup_max_iterations = 60;
    o.mutual_iterations = 16;
    o.schedule_2d = {10, 50, 10, 30, 0.05f};
    o.schedule_3d = {10, 50, 5, 30, 0.005f};
    MutualBoostedSolver full(o, scene);
    SolveSummary s_full;
    ASSERT_TRUE(full.Solve(&s_full).ok());
    for (Stage stage : {Stage::kWarmup, Stage::kMutual}) {
      const int at = stage == Stage::kWarmup ? 37 : 7;
      MutualBoostedSolver first(o, scene);
      StopAt stop(&first, stage, at);
      first.AddCallback(&stop);
      SolveSummary s1;
      ASSERT_TRUE(first.Solve(&s1).ok());
      EXPECT_EQ(s1.termination_type, TerminationType::kInterrupted);
      EXPECT_EQ(s1.message, std::string("after ") +
                                (stage == Stage::kWarmup ? "warm-up" : "mutual") + " iteration " +
                                std::to_string(at));
      const std::string ckpt = dir + "/run.ckpt";
      ASSERT_TRUE(first.SaveCheckpoint(ckpt).ok());
      // A fresh solver (a new process, in practice) continues from the file.
      MutualBoostedSolver second(o, scene);
      ASSERT_TRUE(second.LoadCheckpoint(ckpt).ok());
      SolveSummary s2;
      ASSERT_TRUE(second.Solve(&s2).ok());
      ExpectSameModels(full, second);
      EXPECT_EQ(s2.branch(Branch::kSurfels2D).warmup_iterations,
                s_full.branch(Branch::kSurfels2D).warmup_iterations);
      EXPECT_EQ(s2.mutual_iterations, s_full.mutual_iterations);
      for (int v : scene.TrainIndices()) {
        EXPECT_EQ(full.exposure(Branch::kGaussians3D).transform(v),
                  second.exposure(Branch::kGaussians3D).transform(v));
      }
    }
  }
}

TEST(MutualBoostedSolverTest, ASurfelLayerRowMovesTheDisksAndIsRefusedOnTheGaussians) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 30;
  o.mutual_iterations = 4;
  MutualBoostedSolver without(o, scene);
  SolveSummary s;
  ASSERT_TRUE(without.Solve(&s).ok()) << s.message;
  o.lambda_surfel_layer = 3;
  MutualBoostedSolver with(o, scene);
  Recorder record;
  with.AddCallback(&record);
  ASSERT_TRUE(with.Solve(&s).ok()) << s.message;
  ASSERT_FALSE(record.calls.empty());
  bool reported = false;
  for (const IterationInfo& i : record.calls)
    for (const auto& term : i.terms) reported |= term.name == "surfel_layer" && term.value > 0;
  EXPECT_TRUE(reported);
  EXPECT_NE(without.surfels().means, with.surfels().means);

  // The prior reads disks: a row on the 3DGS branch stops the run before it starts.
  o.lambda_surfel_layer = 0;
  o.losses = PaperLossTable(o);
  LossSpec row;
  row.branch = Branch::kGaussians3D;
  row.stage = Stage::kMutual;
  row.name = "layer";
  row.term = "surfel_layer";
  row.weight = 1;
  o.losses.push_back(row);
  MutualBoostedSolver refused(o, scene);
  const Status status = refused.Solve(&s);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("3d/mutual/layer"), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("log_scales"), std::string::npos) << status.message();
}

TEST(CheckpointTest, BadCheckpointsAreRefused) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  MutualBoostedSolver solver(TinyOptions(), scene);
  ASSERT_TRUE(solver.SaveCheckpoint(dir + "/ok.ckpt").ok());
  std::string data;
  ASSERT_TRUE(ReadFileToString(dir + "/ok.ckpt", &data).ok());
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/cut.ckpt", data.substr(0, data.size() / 2)).ok());
  Status s = solver.LoadCheckpoint(dir + "/cut.ckpt");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("truncated"), std::string::npos) << s.message();
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/junk.ckpt", "hello world, not a checkpoint").ok());
  s = solver.LoadCheckpoint(dir + "/junk.ckpt");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not an MGSR checkpoint"), std::string::npos) << s.message();
  EXPECT_TRUE(solver.LoadCheckpoint(dir + "/ok.ckpt").ok());
}

// #18: a checkpoint carries its options, its scene's fingerprint and a checksum, and every value is
// checked before the solver takes any of it.
std::string Reseal(const std::string& body) { return body + Sha256Hex(body); }
std::string Body(const std::string& data) { return data.substr(0, data.size() - 64); }

void ExpectRefused(MutualBoostedSolver* solver, const std::string& path, const std::string& bytes,
                   const std::string& expected) {
  ASSERT_TRUE(WriteStringToFileAtomic(path, bytes).ok());
  const Status s = solver->LoadCheckpoint(path);
  ASSERT_FALSE(s.ok()) << expected;
  EXPECT_EQ(s.message().rfind(path + ": ", 0), 0u) << s.message();
  EXPECT_NE(s.message().find(expected), std::string::npos) << s.message();
}

TEST(CheckpointTest, MismatchedAndDamagedCheckpointsAreRefused) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 12;
  o.mutual_iterations = 4;
  MutualBoostedSolver writer(o, scene);
  StopAt stop(&writer, Stage::kWarmup, 6);
  writer.AddCallback(&stop);
  SolveSummary summary;
  ASSERT_TRUE(writer.Solve(&summary).ok());  // interrupted, with Adam steps taken
  ASSERT_EQ(summary.termination_type, TerminationType::kInterrupted);
  const std::string ckpt = dir + "/ok.ckpt";
  ASSERT_TRUE(writer.SaveCheckpoint(ckpt).ok());
  std::string data;
  ASSERT_TRUE(ReadFileToString(ckpt, &data).ok());
  MutualBoostedSolver reader(o, scene);
  ASSERT_TRUE(reader.LoadCheckpoint(ckpt).ok());
  const std::string bad = dir + "/bad.ckpt";

  // One flipped bit anywhere.
  std::string flipped = data;
  flipped[flipped.size() / 2] ^= 1;
  ExpectRefused(&reader, bad, flipped, "checksum does not match (corrupt or truncated checkpoint)");

  // Other options: the differing one is named, with both values.
  for (auto edit : std::vector<std::pair<std::string, void (*)(SolverOptions*)>>{
           {"seed = 0, this run has seed = 5", [](SolverOptions* x) { x->seed = 5; }},
           {"mutual_iterations = 4, this run has mutual_iterations = 3",
            [](SolverOptions* x) { x->mutual_iterations = 3; }},
           {"train_3d = 1, this run has train_3d = 0",
            [](SolverOptions* x) { x->train_3d = false; }},
       }) {
    SolverOptions other = o;
    edit.second(&other);
    MutualBoostedSolver s(other, scene);
    ExpectRefused(&s, bad, data, "the checkpoint was written with " + edit.first);
  }

  // A budget the pipeline derives from the scene: the message names the flags that move it.
  {
    SolverOptions other = o;
    other.max_gaussians = o.max_gaussians + 1;
    MutualBoostedSolver s(other, scene);
    ExpectRefused(&s, bad, data,
                  "(derived from the scene's size in pixels and --budget: did "
                  "--downscale, --max_size, --max_width, --budget or the photos change?)");
  }

  // Another scene: a moved camera, or another scene altogether.
  Scene moved = scene;
  moved.views[3].camera.fx *= 1.01;
  MutualBoostedSolver on_moved(o, moved);
  ExpectRefused(&on_moved, bad, data,
                "view '" + scene.views[3].name + "' has another size, camera or split");
  Scene renamed = scene;
  renamed.views[0].name = "other.png";
  MutualBoostedSolver on_renamed(o, renamed);
  ExpectRefused(&on_renamed, bad, data, "the checkpoint was written for another scene");

  // Values no run can produce, behind a valid checksum.
  std::string body = Body(data);
  const std::string last_view = scene.views.back().name + std::string(1, '\0');
  const size_t header_end = body.find(last_view) + last_view.size() + 65;  // + fingerprint
  int32_t next = 99;  // after the training-view count and the stage
  std::string edited = body;
  std::memcpy(&edited[header_end + 8], &next, sizeof(next));
  ExpectRefused(&reader, bad, Reseal(edited), "next iteration 99");

  // Written before an option existed: accepted when the run has the value runs had before it
  // (the coarse start: none; the warm-up's own silhouette weight and the 2DGS branch's own
  // position decay: none, -1; the surfels' shape decay and the agreement-weighted normal prior:
  // off), refused otherwise.
  {
    std::string old_body = Body(data);
    for (const std::string line :
         {"coarse = none\n", "lambda_mask_warmup = -1\n", "position_lr_max_steps_2d = -1\n",
          "surfel_shape_decay = 0\n", "normal_agreement_floor = 1\n"}) {
      const size_t at = old_body.find(line);
      ASSERT_NE(at, std::string::npos) << line;
      old_body.erase(at, line.size());
    }
    ASSERT_TRUE(WriteStringToFileAtomic(bad, Reseal(old_body)).ok());
    MutualBoostedSolver old_reader(o, scene);
    EXPECT_TRUE(old_reader.LoadCheckpoint(bad).ok());
    SolverOptions with_warmup_weight = o;
    with_warmup_weight.lambda_mask_warmup = 10;
    MutualBoostedSolver s(with_warmup_weight, scene);
    ExpectRefused(&s, bad, Reseal(old_body),
                  "the checkpoint does not record option lambda_mask_warmup");
    SolverOptions with_own_decay = o;
    with_own_decay.position_lr_max_steps_2d = 2250;
    MutualBoostedSolver d(with_own_decay, scene);
    ExpectRefused(&d, bad, Reseal(old_body),
                  "the checkpoint does not record option position_lr_max_steps_2d");
    SolverOptions with_shape_decay = o;
    with_shape_decay.surfel_shape_decay = true;
    MutualBoostedSolver sd(with_shape_decay, scene);
    ExpectRefused(&sd, bad, Reseal(old_body),
                  "the checkpoint does not record option surfel_shape_decay");
    SolverOptions with_agreement = o;
    with_agreement.normal_agreement_floor = 0.25;
    MutualBoostedSolver ag(with_agreement, scene);
    ExpectRefused(&ag, bad, Reseal(old_body),
                  "the checkpoint does not record option normal_agreement_floor");
  }
  // Finished in the warm-up; then the random generator's state 0 (stage, next iteration and
  // finished flag, the SH degree, the summary's mutual count and three times, then the state).
  edited = body;
  edited[header_end + 12] = 1;
  ExpectRefused(&reader, bad, Reseal(edited), "marked finished at stage 0");
  edited = body;
  const uint64_t zero = 0;
  std::memcpy(&edited[header_end + 13 + 4 + sizeof(int) + 3 * sizeof(double)], &zero, 8);
  ExpectRefused(&reader, bad, Reseal(edited), "random generator state 0");
  // The surfel optimiser's position block (the last one named "means", width 3): its step.
  const std::string means = std::string("means", 6) + std::string("\x03\0\0\0", 4);
  const size_t at = body.rfind(means);
  ASSERT_NE(at, std::string::npos);
  int64_t step = -5;
  edited = body;
  std::memcpy(&edited[at + means.size()], &step, sizeof(step));
  ExpectRefused(&reader, bad, Reseal(edited), "optimiser state of 'means'");

  // A NaN parameter.
  MutualBoostedSolver poisoned(o, scene);
  poisoned.mutable_surfels()->opacity_logits[2] = std::nanf("");
  ASSERT_TRUE(poisoned.SaveCheckpoint(bad).ok());
  const Status s = reader.LoadCheckpoint(bad);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("NaN or infinite values in parameter block 'opacity_logits'"),
            std::string::npos)
      << s.message();
  // Nothing of the refused files reached the reader: it still continues as the writer would.
  ASSERT_TRUE(reader.LoadCheckpoint(ckpt).ok());
}

// A NaN that gets into a parameter stops the run at the next step with an error naming the branch,
// the iteration and the block, instead of training on and writing NaN models.
class PoisonAt : public IterationCallback {
 public:
  PoisonAt(MutualBoostedSolver* solver, int iteration) : solver_(solver), iteration_(iteration) {}
  CallbackReturnType operator()(const IterationInfo& i) override {
    if (i.stage == Stage::kWarmup && i.iteration == iteration_ &&
        i.branch == Branch::kGaussians3D) {
      for (float& x : solver_->mutable_surfels()->opacity_logits) x = std::nanf("");
    }
    return CallbackReturnType::kContinue;
  }

 private:
  MutualBoostedSolver* solver_;
  int iteration_;
};

TEST(MutualBoostedSolverTest, ANonFiniteValueStopsTheRun) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 20;
  MutualBoostedSolver solver(o, scene);
  PoisonAt poison(&solver, 7);
  solver.AddCallback(&poison);
  SolveSummary summary;
  const Status s = solver.Solve(&summary);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message().rfind("non-finite", 0), 0u) << s.message();
  EXPECT_NE(s.message().find("2DGS warm-up iteration 8"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("the last checkpoint is the last good state"), std::string::npos);
}

// As mgsr_solve runs it: a checkpoint every 5 iterations (stop, save, continue). The NaN that
// appears after iteration 7 stops the run at 8, before any checkpoint can hold it; the file on
// disk is still iteration 5's state, loads (its validation refuses non-finite values), and a
// fresh solver finishes the run from it.
TEST(MutualBoostedSolverTest, ANonFiniteValueLeavesTheLastGoodCheckpoint) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 20;
  const std::string ckpt = dir + "/run.ckpt";
  MutualBoostedSolver solver(o, scene);
  StopAt stop(&solver, Stage::kWarmup, 5);
  PoisonAt poison(&solver, 7);
  solver.AddCallback(&stop);
  solver.AddCallback(&poison);
  SolveSummary summary;
  Status s = solver.Solve(&summary);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(summary.termination_type, TerminationType::kInterrupted);
  ASSERT_TRUE(solver.SaveCheckpoint(ckpt).ok());
  s = solver.Solve(&summary);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message().rfind("non-finite", 0), 0u) << s.message();
  MutualBoostedSolver resumed(o, scene);
  ASSERT_TRUE(resumed.LoadCheckpoint(ckpt).ok());
  SolveSummary finished;
  ASSERT_TRUE(resumed.Solve(&finished).ok());
  EXPECT_EQ(finished.branch(Branch::kSurfels2D).warmup_iterations, 20);
  for (float x : resumed.surfels().opacity_logits) ASSERT_TRUE(std::isfinite(x));
}

// The mean prior fixes the gauge: a gradient that pushes every view's gain down alike (the scene
// could absorb it) moves the gains without it and barely with it; one view's own deviation stays.
TEST(ExposureModelTest, MeanPriorHoldsTheAverageTransformAtIdentity) {
  for (double mean_prior : {0.0, 10.0}) {
    ExposureModel ex;
    ex.Reset(5, ExposureMode::kDiagonal, {0, 1, 2, 3});  // view 4 is a test view
    ColorTransform g{};
    for (int step = 0; step < 200; ++step) {
      for (int v = 0; v < 4; ++v) {
        g[0] = v == 2 ? 0.5 : 0.1;  // view 2 is darker than the rest
        ex.Step(v, g, 5e-3, 1e-3, 1.0, mean_prior);
      }
    }
    double mean = 0;
    for (int v = 0; v < 4; ++v) mean += ex.transform(v)[0] / 4;
    if (mean_prior == 0) {
      EXPECT_LT(mean, 0.5);
    } else {
      EXPECT_NEAR(mean, 1.0, 0.05);
      EXPECT_LT(ex.transform(2)[0], ex.transform(0)[0] - 0.1);
    }
    EXPECT_EQ(ex.transform(4), IdentityColorTransform());
    EXPECT_EQ(ex.transform(0)[1], 0.0);  // diagonal mode: off-diagonal held
  }
}

// The exposure fit alone: a photo that is the render under a known transform (per-channel gains
// with or without offsets, or a full colour matrix), with 5% of its foreground replaced by
// highlights the transform cannot explain.
TEST(ExposureFitTest, RecoversKnownTransformsDespiteHighlights) {
  const Scene scene = TinyScene(testing::ScratchDir());
  const View& v = scene.views[1];
  const Image render = CompositeOnBackground(v, 0.0f);
  struct Case {
    ExposureMode mode;
    ColorTransform truth;
    double offset_prior;
  };
  const Case cases[] = {
      {ExposureMode::kDiagonal, {0.62, 0, 0, 0, 0.81, 0, 0, 0, 0.93, 0, 0, 0}, 1.0},
      {ExposureMode::kDiagonal, {0.62, 0, 0, 0, 0.81, 0, 0, 0, 0.93, 0.03, -0.02, 0.01}, 0.0},
      {ExposureMode::kAffine,
       {0.62, 0.08, 0, 0, 0.81, -0.06, 0.05, 0, 0.93, 0.03, -0.02, 0.01},
       0.0},
  };
  Rng rng(3);
  for (const Case& k : cases) {
    SCOPED_TRACE(std::string(ExposureModeName(k.mode)) + " offset prior " +
                 std::to_string(k.offset_prior));
    Image photo;
    ApplyColorTransform(k.truth, render, &v.mask, &photo);
    std::vector<uint8_t> outlier(photo.plane_size(), 0);
    for (size_t i = 0; i < photo.plane_size(); ++i) {
      if (v.mask.plane(0)[i] > 0.5f && rng.Uniform() < 0.05) {
        outlier[i] = 1;
        for (int c = 0; c < 3; ++c) photo.plane(c)[i] = std::min(0.98f, photo.plane(c)[i] + 0.5f);
      }
    }
    ExposureFitOptions fo;
    fo.mode = k.mode;
    fo.offset_prior = k.offset_prior;
    ColorTransform fitted;
    ExposureFitSummary summary;
    ASSERT_TRUE(FitColorTransform(render, photo, &v.mask, fo, &fitted, &summary).ok());
    EXPECT_GT(summary.samples, 100);
    for (int i : {0, 4, 8}) EXPECT_NEAR(fitted[i] / k.truth[i], 1.0, 0.02) << "gain " << i;
    // The mapped colours of the inlier pixels (off-diagonal terms of correlated channels are not
    // individually determined; what they do to the image is).
    Image mapped;
    ApplyColorTransform(fitted, render, &v.mask, &mapped);
    double err = 0;
    int n = 0;
    for (size_t i = 0; i < photo.plane_size(); ++i) {
      if (outlier[i] || v.mask.plane(0)[i] <= 0.5f) continue;
      for (int c = 0; c < 3; ++c) err += std::abs(mapped.plane(c)[i] - photo.plane(c)[i]);
      n += 3;
    }
    EXPECT_LT(err / n, 0.005);
    if (k.mode == ExposureMode::kDiagonal) {
      EXPECT_EQ(fitted[1], 0.0);  // held at identity
    }
    // The fit is the minimum of its robust cost: with every usable pixel a sample, moving any
    // free parameter either way from it costs more (the cost written out from its definition).
    fo.max_samples = 1 << 30;
    ASSERT_TRUE(FitColorTransform(render, photo, &v.mask, fo, &fitted, &summary).ok());
    auto cost = [&](const ColorTransform& p) {
      double c = 0;
      int used = 0;
      for (size_t i = 0; i < photo.plane_size(); ++i) {
        if (!(v.mask.plane(0)[i] > fo.mask_threshold)) continue;
        if (std::max({photo.plane(0)[i], photo.plane(1)[i], photo.plane(2)[i]}) >= fo.saturation)
          continue;
        double s = 0;
        for (int o = 0; o < 3; ++o) {
          const double r = p[3 * o] * render.plane(0)[i] + p[3 * o + 1] * render.plane(1)[i] +
                           p[3 * o + 2] * render.plane(2)[i] + p[9 + o] - photo.plane(o)[i];
          s += r * r;
        }
        const double d = fo.huber_delta;
        c += s <= d * d ? s : 2 * d * std::sqrt(s) - d * d;
        ++used;
      }
      for (int o = 0; o < 3; ++o) c += fo.offset_prior * used * p[9 + o] * p[9 + o];
      return 0.5 * c;
    };
    const double at_fit = cost(fitted);
    EXPECT_NEAR(summary.final_cost, at_fit, 1e-9 * at_fit);
    for (int j = 0; j < kColorTransformSize; ++j) {
      if (!ColorTransformParameterIsFree(k.mode, j)) continue;
      for (double step : {-1e-4, 1e-4}) {
        ColorTransform moved = fitted;
        moved[j] += step;
        EXPECT_GT(cost(moved), at_fit) << "parameter " << j << " moved by " << step;
      }
    }
  }
  ColorTransform p;
  EXPECT_FALSE(FitColorTransform(render, Image(3, 3, 3), nullptr, ExposureFitOptions(), &p).ok());
}

// Relative gain errors: per view and channel the ratio estimate / truth, normalised by its median
// over the views (the scene's colours and the transforms share one free scale), then |r - 1|.
std::vector<double> RelativeGainErrors(const std::map<int, std::array<double, 3>>& truth,
                                       const std::function<double(int, int)>& estimate) {
  std::vector<double> errors;
  for (int c = 0; c < 3; ++c) {
    std::vector<double> ratios;
    for (const auto& [v, g] : truth) ratios.push_back(estimate(v, c) / g[c]);
    std::vector<double> sorted = ratios;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double median = sorted[sorted.size() / 2];
    for (double r : ratios) errors.push_back(std::abs(r / median - 1));
  }
  return errors;
}

double Median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// The whole solver on a scene whose training photos differ only by known per-channel gains: the
// learned transforms move towards the truth. How close they get is bounded by how well the model
// renders each view: on this 64 px scene after 500 iterations (training views at 23-29 dB), the
// median view is within about 5% and a view the model renders with floaters (v001) 15-30% off;
// the Ceres fit itself is exact to 2% against a faithful render (ExposureFitTest).
TEST(MutualBoostedSolverTest, ExposureCompensationLearnsKnownGains) {
  const std::string dir = testing::ScratchDir();
  SynthOptions so = testing::SmallSynthOptions();
  so.width = so.height = 64;
  so.varying_light = false;
  so.num_views = 24;
  so.specular = 0.0;  // a diffuse object: what differs between photos is the gain alone
  ASSERT_TRUE(WriteSyntheticScene(so, dir).ok());
  Scene scene;
  ASSERT_TRUE(LoadScene(dir, SceneOptions(), &scene).ok());
  Rng rng(5);
  std::map<int, std::array<double, 3>> gains;
  for (int v : scene.TrainIndices()) {
    std::array<double, 3>& g = gains[v];
    for (int c = 0; c < 3; ++c) {
      g[c] = rng.Uniform(0.55, 1.0);  // darker only: nothing clips
      float* plane = scene.views[v].image.plane(c);
      for (size_t i = 0; i < scene.views[v].image.plane_size(); ++i) plane[i] *= g[c];
    }
  }
  SolverOptions o = TinyOptions();
  o.exposure = ExposureMode::kDiagonal;
  o.warmup_max_iterations = o.warmup_min_iterations = 500;
  o.mutual_iterations = 60;
  o.schedule_2d = {20, 300, 20, 1000, 0.05f};
  o.schedule_3d = {20, 300, 10, 1000, 0.005f};
  MutualBoostedSolver solver(o, scene);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  EXPECT_GT(summary.exposure_fit_seconds, 0.0);
  const ExposureModel& ex = solver.exposure(Branch::kGaussians3D);
  const std::vector<double> learned =
      RelativeGainErrors(gains, [&](int v, int c) { return ex.transform(v)[4 * c]; });
  const std::vector<double> none = RelativeGainErrors(gains, [](int, int) { return 1.0; });
  std::printf(
      "exposure: relative gain error median %.1f%% (without compensation %.1f%%), "
      "max %.1f%%\n",
      100 * Median(learned), 100 * Median(none),
      100 * *std::max_element(learned.begin(), learned.end()));
  EXPECT_LT(Median(learned), 0.5 * Median(none));
  EXPECT_LT(Median(learned), 0.08);
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {
TEST(CheckpointTest, TwoRunsAreIdentical) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 60;
  o.mutual_iterations = 16;
  MutualBoostedSolver a(o, scene), b(o, scene);
  SolveSummary sa, sb;
  ASSERT_TRUE(a.Solve(&sa).ok());
  ASSERT_TRUE(b.Solve(&sb).ok());
  ExpectSameModels(a, b);
}
}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// Snapshots both models at every mutual-stage notification.
class Snapshots : public IterationCallback {
 public:
  explicit Snapshots(const MutualBoostedSolver* s) : solver_(s) {}
  CallbackReturnType operator()(const IterationInfo& i) override {
    if (i.stage != Stage::kMutual) return CallbackReturnType::kContinue;
    branches.push_back(i.branch);
    gaussian_means.push_back(solver_->gaussians().means);
    surfel_means.push_back(solver_->surfels().means);
    return CallbackReturnType::kContinue;
  }
  std::vector<Branch> branches;
  std::vector<std::vector<float>> gaussian_means, surfel_means;

 private:
  const MutualBoostedSolver* solver_;
};

TEST(MutualBoostedSolverTest, BidirectionalChangesWhichBranchesLearn) {
  const Scene scene = TinyScene(testing::ScratchDir());
  for (bool bidirectional : {false, true}) {
    SolverOptions o = TinyOptions();
    o.warmup_max_iterations = 6;
    o.mutual_iterations = 3;  // alternate: 2DGS, 3DGS, 2DGS
    o.bidirectional = bidirectional;
    MutualBoostedSolver solver(o, scene);
    Snapshots snap(&solver);
    solver.AddCallback(&snap);
    SolveSummary summary;
    ASSERT_TRUE(solver.Solve(&summary).ok());
    ASSERT_EQ(snap.branches.size(), 3u);
    // Iteration 2 steps the 3DGS branch: does the 2DGS branch move too?
    const bool surfels_moved = snap.surfel_means[1] != snap.surfel_means[0];
    // Iteration 3 steps the 2DGS branch: does the 3DGS branch move too?
    const bool gaussians_moved = snap.gaussian_means[2] != snap.gaussian_means[1];
    EXPECT_EQ(surfels_moved, bidirectional);
    EXPECT_EQ(gaussians_moved, bidirectional);
  }
}

}  // namespace
}  // namespace mgsr

#include <omp.h>

namespace mgsr {
namespace {

TEST(CheckpointTest, OneAndTwoThreadsGiveIdenticalModels) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 40;
  o.mutual_iterations = 10;
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  MutualBoostedSolver one(o, scene);
  SolveSummary s1;
  ASSERT_TRUE(one.Solve(&s1).ok());
  omp_set_num_threads(2);
  MutualBoostedSolver two(o, scene);
  SolveSummary s2;
  ASSERT_TRUE(two.Solve(&s2).ok());
  omp_set_num_threads(saved);
  ExpectSameModels(one, two);
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// A term a researcher might add: the mean accumulated opacity (pulls the render transparent).
using testing::MeanAlphaLoss;

double MeanSurfelAlpha(MutualBoostedSolver* solver, const Scene& scene) {
  double sum = 0;
  for (int i : scene.TrainIndices()) {
    SurfelRender r;
    solver->RenderSurfels(scene.views[i].camera, &r);
    for (size_t k = 0; k < r.alpha.size(); ++k) sum += r.alpha.data()[k] / r.alpha.size();
  }
  return sum / scene.TrainIndices().size();
}

// A new term trains through a row of the loss table: it is switched on at its first iteration, its
// value shows in the per-row breakdown, the breakdown sums to the loss, and it changes the model.
TEST(LossTableSolverTest, ANewTermTrainsThroughARow) {
  LossRegistry::Get().Register("test_mean_alpha", [](const nlohmann::json&, Status*) {
    return std::make_unique<MeanAlphaLoss>();
  });
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions plain = TinyOptions();
  plain.warmup_max_iterations = 80;
  plain.mutual_iterations = 10;
  SolverOptions with = plain;
  with.losses = with.LossTable();
  ASSERT_TRUE(ApplyLossConfig(nlohmann::json::parse(R"({"losses": [{"branch": "2d",
      "stage": "both", "name": "thin", "term": "test_mean_alpha", "weight": 0.5,
      "first_iteration": 30}]})"),
                              "test", &with.losses)
                  .ok());
  MutualBoostedSolver a(plain, scene), b(with, scene);
  Recorder rec;
  b.AddCallback(&rec);
  SolveSummary sa, sb;
  ASSERT_TRUE(a.Solve(&sa).ok());
  ASSERT_TRUE(b.Solve(&sb).ok());
  int with_row = 0;
  for (const IterationInfo& i : rec.calls) {
    if (i.branch != Branch::kSurfels2D) continue;
    double sum = 0;
    bool has = false;
    for (const Problem::TermValue& t : i.terms) {
      sum += t.weight * t.value;
      has = has || t.name == "thin";
    }
    EXPECT_NEAR(sum, i.loss, 1e-6 * std::abs(i.loss)) << i.iteration;
    // "both" gives the mutual row the same first iteration, which 10 mutual ones do not reach.
    const bool expected = i.stage == Stage::kWarmup && i.iteration >= 30;
    EXPECT_EQ(has, expected) << StageName(i.stage) << " " << i.iteration;
    with_row += has;
  }
  EXPECT_EQ(with_row, 51);
  EXPECT_LT(MeanSurfelAlpha(&b, scene), MeanSurfelAlpha(&a, scene) - 0.01);
}

// The paper's table written out as rows trains exactly as the default (empty) table.
TEST(LossTableSolverTest, TheExplicitPaperTableEqualsTheDefault) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 40;
  o.mutual_iterations = 10;
  SolverOptions explicit_table = o;
  explicit_table.losses = PaperLossTable(o);
  MutualBoostedSolver a(o, scene), b(explicit_table, scene);
  SolveSummary sa, sb;
  ASSERT_TRUE(a.Solve(&sa).ok());
  ASSERT_TRUE(b.Solve(&sb).ok());
  ExpectSameModels(a, b);
}

// A row whose inputs the branch does not render, or whose target the stage does not have, stops
// the run at its first step with the row's name.
TEST(LossTableSolverTest, ARowTheBranchCannotFeedStopsTheRunNamingIt) {
  const Scene scene = TinyScene(testing::ScratchDir());
  const std::vector<std::pair<std::string, std::string>> rows = {
      {R"({"branch": "2d", "stage": "warmup", "name": "refl", "term": "l1",
          "config": {"buffer": "reflected"}, "weight": 1})",
       "2DGS warmup loss row refl: "},
      {R"({"branch": "3d", "stage": "warmup", "name": "vs_depth", "term": "mutual_depth",
          "weight": 1})",
       "3DGS warmup loss row vs_depth: "},
  };
  for (const auto& [row, expected] : rows) {
    SolverOptions o = TinyOptions();
    o.warmup_max_iterations = 5;
    o.losses = o.LossTable();
    ASSERT_TRUE(
        ApplyLossConfig({{"losses", {nlohmann::json::parse(row)}}}, "test", &o.losses).ok());
    MutualBoostedSolver solver(o, scene);
    SolveSummary summary;
    const Status s = solver.Solve(&summary);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find(expected), std::string::npos) << s.message();
  }
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// Returns `request` at one step.
class RequestAt : public IterationCallback {
 public:
  RequestAt(Stage stage, int iteration, Branch branch, CallbackReturnType request)
      : stage_(stage), iteration_(iteration), branch_(branch), request_(request) {}
  CallbackReturnType operator()(const IterationInfo& i) override {
    const bool here = i.stage == stage_ && i.iteration == iteration_ && i.branch == branch_;
    return here ? request_ : CallbackReturnType::kContinue;
  }

 private:
  Stage stage_;
  int iteration_;
  Branch branch_;
  CallbackReturnType request_;
};

// Ceres-style control: a callback ends the run successfully or aborts it, at the end of the
// iteration (the other branch of it still steps), and the summary says which.
TEST(MutualBoostedSolverTest, ACallbackEndsOrAbortsTheRunAtTheIterationsEnd) {
  const Scene scene = TinyScene(testing::ScratchDir());
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 30;
  {
    MutualBoostedSolver solver(o, scene);
    RequestAt end(Stage::kWarmup, 10, Branch::kSurfels2D,
                  CallbackReturnType::kTerminateSuccessfully);
    solver.AddCallback(&end);
    SolveSummary summary;
    ASSERT_TRUE(solver.Solve(&summary).ok());
    EXPECT_EQ(summary.termination_type, TerminationType::kUserSuccess);
    EXPECT_TRUE(summary.IsFinished());
    EXPECT_EQ(summary.branch(Branch::kSurfels2D).warmup_iterations, 10);
    EXPECT_EQ(summary.branch(Branch::kGaussians3D).warmup_iterations, 10);
    EXPECT_EQ(summary.mutual_iterations, 0);
    EXPECT_NE(summary.FullReport().find("ended by a callback (after warm-up iteration 10)"),
              std::string::npos)
        << summary.FullReport();
    // A finished run stays finished.
    SolveSummary again;
    ASSERT_TRUE(solver.Solve(&again).ok());
    EXPECT_EQ(again.branch(Branch::kSurfels2D).warmup_iterations, 10);
  }
  {
    MutualBoostedSolver solver(o, scene);
    RequestAt abort(Stage::kWarmup, 5, Branch::kSurfels2D, CallbackReturnType::kAbort);
    solver.AddCallback(&abort);
    SolveSummary summary;
    const Status s = solver.Solve(&summary);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.message(), "aborted by an iteration callback after warm-up iteration 5");
    EXPECT_EQ(summary.termination_type, TerminationType::kUserAbort);
    EXPECT_FALSE(summary.IsFinished());
    EXPECT_EQ(summary.branch(Branch::kGaussians3D).warmup_iterations, 5);
  }
}

// CheckpointCallback writes at iteration boundaries: a fresh solver continued from the last file
// it wrote ends with the models of the uninterrupted run.
TEST(CheckpointTest, CheckpointCallbackWritesResumableStates) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  SolverOptions o = TinyOptions();
  o.warmup_max_iterations = 30;
  o.mutual_iterations = 10;
  const std::string ckpt = dir + "/run.ckpt";
  MutualBoostedSolver full(o, scene);
  int saves = 0;
  CheckpointCallback checkpointer(ckpt, 7, [&saves] {
    ++saves;
    return Status::Ok();
  });
  full.AddCallback(&checkpointer);
  SolveSummary s_full;
  ASSERT_TRUE(full.Solve(&s_full).ok());
  EXPECT_EQ(s_full.termination_type, TerminationType::kFinished);
  // 30 warm-up and 10 mutual iterations: written after 7, 14, ..., 35 (warm-up 30 ends at 30).
  EXPECT_EQ(checkpointer.checkpoints_written(), 5);
  EXPECT_EQ(saves, 5);
  MutualBoostedSolver resumed(o, scene);
  ASSERT_TRUE(resumed.LoadCheckpoint(ckpt).ok());
  SolveSummary s;
  ASSERT_TRUE(resumed.Solve(&s).ok());
  ExpectSameModels(full, resumed);
  // A write that fails aborts the run and says why.
  MutualBoostedSolver failing(o, scene);
  CheckpointCallback bad(dir + "/no/such/dir/run.ckpt", 3);
  failing.AddCallback(&bad);
  ASSERT_FALSE(failing.Solve(&s).ok());
  EXPECT_EQ(s.termination_type, TerminationType::kUserAbort);
  EXPECT_FALSE(bad.status().ok());
  EXPECT_NE(bad.status().message().find("no/such/dir"), std::string::npos)
      << bad.status().message();
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// The surfels' blocks only (the 2DGS branch's model).
void ExpectSameSurfels(const MutualBoostedSolver& a, const MutualBoostedSolver& b) {
  SurfelModel sa = a.surfels(), sb = b.surfels();
  ASSERT_EQ(sa.size(), sb.size());
  const auto ca = sa.Blocks(), cb = sb.Blocks();
  for (size_t k = 0; k < ca.size(); ++k) EXPECT_EQ(*ca[k].data, *cb[k].data) << ca[k].name;
}

// Past mutual_iterations_2d the 2DGS branch is where a run that ended there left it, and the
// 3DGS branch trains on; a run stopped and resumed on either side of that point continues exactly.
TEST(MutualBoostedSolverTest, AHeldGeometryBranchStaysWhereItsShareEnded) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = TinyScene(dir + "/scene");
  for (const char* mode : {"alternate", "joint"}) {
    SCOPED_TRACE(mode);
    SolverOptions shorter = TinyOptions();
    shorter.warmup_max_iterations = 40;
    shorter.mutual_mode = mode;
    shorter.mutual_iterations = 8;
    SolverOptions held = shorter;
    held.mutual_iterations = 16;
    held.mutual_iterations_2d = 8;
    ASSERT_TRUE(held.Validate().ok()) << held.Validate().message();
    MutualBoostedSolver a(shorter, scene), b(held, scene);
    Snapshots snap(&b);
    b.AddCallback(&snap);
    SolveSummary sa, sb;
    ASSERT_TRUE(a.Solve(&sa).ok());
    ASSERT_TRUE(b.Solve(&sb).ok());
    EXPECT_EQ(sb.mutual_iterations, 16);
    ExpectSameSurfels(a, b);
    EXPECT_NE(a.gaussians().means, b.gaussians().means);  // it trained on
    // No 2DGS step notified past the hold.
    const size_t steps_2d =
        std::count(snap.branches.begin(), snap.branches.end(), Branch::kSurfels2D);
    EXPECT_EQ(steps_2d, std::string(mode) == "joint" ? 8u : 4u);
    for (int at : {6, 12}) {
      SCOPED_TRACE(at);
      MutualBoostedSolver first(held, scene);
      StopAt stop(&first, Stage::kMutual, at);
      first.AddCallback(&stop);
      SolveSummary s1;
      ASSERT_TRUE(first.Solve(&s1).ok());
      ASSERT_EQ(s1.termination_type, TerminationType::kInterrupted);
      const std::string ckpt = dir + "/held.ckpt";
      ASSERT_TRUE(first.SaveCheckpoint(ckpt).ok());
      MutualBoostedSolver second(held, scene);
      ASSERT_TRUE(second.LoadCheckpoint(ckpt).ok());
      SolveSummary s2;
      ASSERT_TRUE(second.Solve(&s2).ok());
      ExpectSameModels(b, second);
    }
  }
  SolverOptions both_ways = TinyOptions();
  both_ways.mutual_iterations_2d = 4;
  both_ways.bidirectional = true;
  EXPECT_EQ(both_ways.Validate().message(),
            "--mutual_iterations_2d: a held 2DGS branch cannot take --bidirectional's gradient");
  both_ways.bidirectional = false;
  both_ways.mutual_iterations_2d = -2;
  EXPECT_EQ(both_ways.Validate().message(),
            "--mutual_iterations_2d must be >= 0 (or -1: the whole mutual stage)");
}

// Where the views have masks, a mutual stage longer than fast's runs fast first and then trains
// the 3DGS branch alone: the held options differ from fast's only in the stage's length and the
// 2DGS branch's share of it. A schedule the command line changed stays; fast itself, a single
// branch or bidirectional supervision are left as they are.
TEST(SolverOptionsTest, HoldGeometryAtFastOnlyLengthensTheAppearanceBranch) {
  SolverOptions paper, fast;
  ASSERT_TRUE(SolverOptions::FromPreset("paper", &paper));
  ASSERT_TRUE(SolverOptions::FromPreset("fast", &fast));
  EXPECT_EQ(paper.mutual_iterations_2d, -1);
  SolverOptions held = paper;
  ASSERT_TRUE(SolverOptions::HoldGeometryAtFast(&held));
  EXPECT_EQ(held.mutual_iterations_2d, fast.mutual_iterations);
  EXPECT_EQ(held.mutual_iterations, 20000);
  EXPECT_TRUE(held.Validate().ok()) << held.Validate().message();
  const auto fast_settings = fast.Settings();
  const auto held_settings = held.Settings();
  ASSERT_EQ(fast_settings.size(), held_settings.size());
  for (size_t i = 0; i < fast_settings.size(); ++i) {
    const std::string& name = fast_settings[i].first;
    if (name == "mutual_iterations" || name == "mutual_iterations_2d") continue;
    if (name == "position_lr_max_steps_2d") {  // 2,250 given, or -1: position_lr_max_steps
      EXPECT_EQ(held.PositionDecaySteps(Branch::kSurfels2D),
                fast.PositionDecaySteps(Branch::kSurfels2D));
      continue;
    }
    EXPECT_EQ(held_settings[i].second, fast_settings[i].second) << name;
  }
  SolverOptions given = paper;
  given.sh_interval = 300;
  ASSERT_TRUE(SolverOptions::HoldGeometryAtFast(&given));
  EXPECT_EQ(given.sh_interval, 300);
  SolverOptions o = fast;
  EXPECT_FALSE(SolverOptions::HoldGeometryAtFast(&o));
  EXPECT_EQ(o.mutual_iterations_2d, -1);
  o = paper;
  o.bidirectional = true;
  EXPECT_FALSE(SolverOptions::HoldGeometryAtFast(&o));
  o = paper;
  ASSERT_TRUE(SolverOptions::ApplyMethod("2dgs", &o));
  EXPECT_FALSE(SolverOptions::HoldGeometryAtFast(&o));
  // Scaled for batches like the stage it belongs to.
  held.ScaleIterationsForBatch(4);
  EXPECT_EQ(held.mutual_iterations_2d, 375);
  EXPECT_EQ(held.mutual_iterations, 5000);
}

}  // namespace
}  // namespace mgsr
