// The coarse start: the views at a coarser level (solvers/view_levels.h), the schedule that says
// which iterations train on them (SolverOptions::CoarseAt), and the solver that switches.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "mean_alpha_loss.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/loss/loss_util.h"
#include "same_models.h"
#include "short_run.h"
#include "solvers/loss_table.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/view_levels.h"
#include "test_util.h"

namespace mgsr {
namespace {

Camera TestCamera(int width, int height) {
  Camera c;
  c.width = width;
  c.height = height;
  c.fx = 100;
  c.fy = 90;
  c.cx = width / 2.0;
  c.cy = height / 2.0;
  return c;
}

TEST(ViewLevelTest, DownscaledViewsAverageBlocksAndScaleCameras) {
  Scene scene;
  View v;
  v.camera = TestCamera(8, 6);
  v.image = Image(8, 6, 3);
  v.mask = Image(8, 6, 1);
  for (int c = 0; c < 3; ++c) {
    for (int y = 0; y < 6; ++y) {
      for (int x = 0; x < 8; ++x) v.image.plane(c)[y * 8 + x] = 0.01f * (x + 8 * y) + 0.1f * c;
    }
  }
  for (int y = 0; y < 6; ++y) {
    for (int x = 0; x < 8; ++x) v.mask.plane(0)[y * 8 + x] = x < 3 ? 1.0f : 0.0f;
  }
  scene.views.push_back(v);
  View plain = v;
  plain.mask = Image();
  scene.views.push_back(plain);

  const ViewLevel full = ViewLevel::FullSize(scene, 1.0f, 0.0f);
  EXPECT_EQ(full.factor(), 1);
  EXPECT_EQ(full.mask(0), &scene.views[0].mask);  // borrowed, not copied
  EXPECT_EQ(full.mask(1), nullptr);
  ViewLevel coarse = ViewLevel::Downscaled(full, 2);
  EXPECT_EQ(coarse.factor(), 2);
  const Camera& c = coarse.camera(0);
  EXPECT_EQ(c.width, 4);
  EXPECT_EQ(c.height, 3);
  EXPECT_DOUBLE_EQ(c.fx, 50);
  EXPECT_DOUBLE_EQ(c.fy, 45);
  EXPECT_DOUBLE_EQ(c.cx, 2);
  EXPECT_DOUBLE_EQ(c.cy, 1.5);
  // Each coarse pixel is the mean of its 2x2 block, in every channel and for both branches.
  for (int branch = 0; branch < 2; ++branch) {
    const Image& p = coarse.photo(0, branch);
    ASSERT_EQ(p.width(), 4);
    ASSERT_EQ(p.height(), 3);
    for (int ch = 0; ch < 3; ++ch) {
      for (int y = 0; y < 3; ++y) {
        for (int x = 0; x < 4; ++x) {
          const float mean = 0.01f * ((2 * x + 0.5f) + 8 * (2 * y + 0.5f)) + 0.1f * ch;
          EXPECT_NEAR(p.plane(ch)[y * 4 + x], mean, 1e-6) << x << "," << y << " ch " << ch;
        }
      }
    }
  }
  // The mask edge at x = 3 falls inside coarse column 1: half covered.
  ASSERT_NE(coarse.mask(0), nullptr);
  EXPECT_FLOAT_EQ(coarse.mask(0)->plane(0)[0], 1.0f);
  EXPECT_FLOAT_EQ(coarse.mask(0)->plane(0)[1], 0.5f);
  EXPECT_FLOAT_EQ(coarse.mask(0)->plane(0)[2], 0.0f);
  EXPECT_EQ(coarse.mask(1), nullptr);
  // Greys of the coarse photos, made on demand; moving the level keeps its masks valid.
  EXPECT_FALSE(coarse.has_grays(1));
  coarse.MakeGrays(1);
  ASSERT_TRUE(coarse.has_grays(1));
  const Image& p = coarse.photo(0, 1);
  EXPECT_NEAR(coarse.gray(0, 1).plane(0)[5],
              0.299f * p.plane(0)[5] + 0.587f * p.plane(1)[5] + 0.114f * p.plane(2)[5], 1e-6);
  const ViewLevel moved = std::move(coarse);
  EXPECT_FLOAT_EQ(moved.mask(0)->plane(0)[1], 0.5f);
}

// The mutual stage's target outside the mask: the background where the mask is 0, the render
// where it is 1 (to the bit), and their mixture on a soft edge (a coarse level's or a resized
// capture's mask).
TEST(ViewLevelTest, CompositeOverMaskMixesOnSoftEdgesOnly) {
  Image mask(4, 1, 1), image(4, 1, 2);
  const float m[4] = {0.0f, 0.25f, 1.0f, 0.5f};
  for (int x = 0; x < 4; ++x) {
    mask.plane(0)[x] = m[x];
    image.plane(0)[x] = 0.1f + 0.2f * x;
    image.plane(1)[x] = 0.3f;
  }
  image.plane(0)[0] = std::nanf("");  // replaced, not mixed
  const Image before = image;
  CompositeOverMask(mask, 0.8f, &image);
  for (int c = 0; c < 2; ++c) {
    EXPECT_EQ(image.plane(c)[0], 0.8f);
    EXPECT_FLOAT_EQ(image.plane(c)[1], 0.25f * before.plane(c)[1] + 0.75f * 0.8f);
    EXPECT_EQ(image.plane(c)[2], before.plane(c)[2]);
    EXPECT_FLOAT_EQ(image.plane(c)[3], 0.5f * before.plane(c)[3] + 0.5f * 0.8f);
  }
}

TEST(ViewLevelTest, CoarseFactorBringsTheLongestTrainingViewWithinTheSize) {
  Scene scene;
  for (const auto& [w, h, test] :
       {std::make_tuple(1600, 1180, false), std::make_tuple(900, 1600, false),
        std::make_tuple(3000, 3000, true)}) {
    View v;
    v.camera = TestCamera(w, h);
    v.is_test = test;
    scene.views.push_back(v);
  }
  EXPECT_EQ(CoarseFactor(scene, 800), 2);  // the test view does not count
  EXPECT_EQ(CoarseFactor(scene, 799), 3);
  EXPECT_EQ(CoarseFactor(scene, 1600), 1);
  EXPECT_EQ(CoarseFactor(scene, 0), 1);
}

TEST(CoarseScheduleTest, TheFirstShareOfEachStageIsCoarseAndRoundsStayWhole) {
  SolverOptions o;
  SolverOptions::FromPreset("fast", &o);
  EXPECT_FALSE(o.CoarseAt(Stage::kWarmup, 1));  // factor 1: never
  o.coarse_factor = 2;
  EXPECT_EQ(o.CoarseWarmupIterations(), 1125);
  EXPECT_TRUE(o.CoarseAt(Stage::kWarmup, 1125));
  EXPECT_FALSE(o.CoarseAt(Stage::kWarmup, 1126));
  // 1,125 mutual iterations would end inside a round (its 2DGS step on 1,125, the 3DGS step on
  // 1,126): alternate rounds switch at a whole round.
  EXPECT_EQ(o.CoarseMutualIterations(), 1124);
  EXPECT_FALSE(o.CoarseAt(Stage::kMutual, 1125));
  o.mutual_mode = "joint";
  EXPECT_EQ(o.CoarseMutualIterations(), 1125);
  o.coarse_fraction = 0;
  EXPECT_FALSE(o.CoarseAt(Stage::kWarmup, 1));
  EXPECT_FALSE(o.CoarseAt(Stage::kMutual, 1));
  o.coarse_fraction = 1.5;
  EXPECT_FALSE(o.Validate().ok());
  o.coarse_fraction = 0.75;
  o.coarse_levels = 0;
  EXPECT_FALSE(o.Validate().ok());
  o.coarse_levels = 9;
  EXPECT_FALSE(o.Validate().ok());
}

TEST(CoarseScheduleTest, TwoLevelsSplitTheCoarseShareCoarsestFirst) {
  SolverOptions o;
  SolverOptions::FromPreset("fast", &o);
  EXPECT_TRUE(o.CoarseFactors().empty());
  EXPECT_EQ(o.CoarseSetting(), "none");
  o.coarse_factor = 2;
  o.coarse_levels = 2;
  EXPECT_EQ(o.CoarseFactors(), (std::vector<int>{4, 2}));
  EXPECT_EQ(o.CoarseLevelFactor(0), 1);
  EXPECT_EQ(o.CoarseSetting(), "2 0.75 2 levels");
  // Warm-up: 1-562 at 1/4, 563-1,125 at 1/2, then full size.
  EXPECT_EQ(o.CoarseLevelEnds(Stage::kWarmup), (std::vector<int>{562, 1125}));
  EXPECT_EQ(o.CoarseLevelAt(Stage::kWarmup, 1), 2);
  EXPECT_EQ(o.CoarseLevelAt(Stage::kWarmup, 562), 2);
  EXPECT_EQ(o.CoarseLevelAt(Stage::kWarmup, 563), 1);
  EXPECT_EQ(o.CoarseLevelAt(Stage::kWarmup, 1125), 1);
  EXPECT_EQ(o.CoarseLevelAt(Stage::kWarmup, 1126), 0);
  // Mutual, alternate: every switch between whole rounds (1,124 / 2 = 562, even).
  EXPECT_EQ(o.CoarseLevelEnds(Stage::kMutual), (std::vector<int>{562, 1124}));
  o.coarse_levels = 3;  // 1,124 / 3 = 374.7 and 749.3: 374 and 748
  EXPECT_EQ(o.CoarseLevelEnds(Stage::kMutual), (std::vector<int>{374, 748, 1124}));
  EXPECT_EQ(o.CoarseLevelAt(Stage::kMutual, 375), 2);
  EXPECT_EQ(o.CoarseFactors(), (std::vector<int>{8, 4, 2}));
  o.mutual_mode = "joint";
  EXPECT_EQ(o.CoarseLevelEnds(Stage::kMutual), (std::vector<int>{375, 750, 1125}));
  // One level: as before, and recorded as before (checkpoints of one-level runs resume).
  o.coarse_levels = 1;
  EXPECT_EQ(o.CoarseLevelEnds(Stage::kWarmup), (std::vector<int>{1125}));
  EXPECT_EQ(o.CoarseSetting(), "2 0.75");
}

// Records the size of every render the 2DGS loss sees, and of the photo and mask it compares.
struct SeenSize {
  int render, photo, mask;
};
std::vector<SeenSize> g_seen;

// Records the sizes, and is the mean alpha otherwise: a registered term must pass the gradient
// harness (tests/loss/loss_test.cc) when tests share a process.
class SizeProbeLoss : public LossTermImpl<SizeProbeLoss> {
 public:
  std::string Name() const override { return "test_size_probe"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kAlpha}; }
  Status Check(const RenderBuffers& in, const Targets&) const override {
    return RequireImage(Name(), "alpha", in.Get(Buffer::kAlpha));
  }
  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    g_seen.push_back({in.Get(Buffer::kAlpha)->width(), t.image ? t.image->width() : -1,
                      t.mask ? t.mask->width() : -1});
    return testing::MeanAlphaLoss().Compute(in, t, scale, grad);
  }
};

struct Iterations : IterationCallback {
  CallbackReturnType operator()(const IterationInfo& i) override {
    if (i.branch == Branch::kSurfels2D) calls.push_back({i.stage, i.iteration});
    return CallbackReturnType::kContinue;
  }
  std::vector<std::pair<Stage, int>> calls;
};

SolverOptions ShortRun() {
  SolverOptions o = testing::ShortFastOptions(40, 12);
  o.schedule_2d = {10, 30, 10, 1000, 0.05f};
  o.schedule_3d = {10, 30, 5, 1000, 0.005f};
  o.sh_interval = 20;
  o.density = "mcmc";
  o.max_gaussians = 400;
  o.max_surfels = 300;
  return o;
}

// Runs the short solve with the size probe and checks the size of every render, photo and mask
// the 2DGS loss saw: `factor_at(stage, iteration)` gives the expected division (1: full size).
void ExpectProbedSizes(const SolverOptions& base, const std::function<int(Stage, int)>& factor_at) {
  LossRegistry::Get().Register("test_size_probe", [](const nlohmann::json&, Status*) {
    return std::make_unique<SizeProbeLoss>();
  });
  const Scene scene = testing::TinySolverScene(testing::ScratchDir());
  const Camera& full = scene.views[scene.TrainIndices()[0]].camera;
  SolverOptions o = base;
  o.losses = o.LossTable();
  ASSERT_TRUE(ApplyLossConfig(nlohmann::json::parse(R"({"losses": [{"branch": "2d",
      "stage": "both", "name": "probe", "term": "test_size_probe", "weight": 1}]})"),
                              "test", &o.losses)
                  .ok());
  g_seen.clear();
  MutualBoostedSolver solver(o, scene);
  Iterations it;
  solver.AddCallback(&it);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  ASSERT_EQ(g_seen.size(), it.calls.size());
  ASSERT_EQ(it.calls.size(), 40u + 6u);  // the 2DGS steps: 40 warm-up, every odd mutual one
  for (size_t k = 0; k < g_seen.size(); ++k) {
    const auto [stage, iteration] = it.calls[k];
    const int expected = CoarseCamera(full, factor_at(stage, iteration)).width;
    SCOPED_TRACE(std::string(StageName(stage)) + " " + std::to_string(iteration));
    EXPECT_EQ(g_seen[k].render, expected);
    EXPECT_EQ(g_seen[k].photo, expected);
    EXPECT_EQ(g_seen[k].mask, scene.views[0].mask.empty() ? -1 : expected);
  }
}

TEST(CoarseStartSolverTest, StepsTrainOnTheCoarseViewsUntilTheSwitch) {
  SolverOptions o = ShortRun();
  o.coarse_factor = 2;
  o.coarse_levels = 1;
  o.coarse_fraction = 0.75;  // warm-up 1-30, mutual 1-8 (of 12: rounds stay whole)
  ExpectProbedSizes(o, [](Stage stage, int iteration) {
    return iteration <= (stage == Stage::kWarmup ? 30 : 8) ? 2 : 1;
  });
}

TEST(CoarseStartSolverTest, TwoLevelsTrainAQuarterSizeThenHalfSizeThenFullSize) {
  SolverOptions o = ShortRun();
  o.coarse_factor = 2;
  o.coarse_levels = 2;
  o.coarse_fraction = 0.75;  // warm-up 1-15 at 1/4, 16-30 at 1/2; mutual 1-4, 5-8
  ASSERT_EQ(o.CoarseLevelEnds(Stage::kWarmup), (std::vector<int>{15, 30}));
  ASSERT_EQ(o.CoarseLevelEnds(Stage::kMutual), (std::vector<int>{4, 8}));
  ExpectProbedSizes(o, [](Stage stage, int iteration) {
    const bool warmup = stage == Stage::kWarmup;
    if (iteration <= (warmup ? 15 : 4)) return 4;
    return iteration <= (warmup ? 30 : 8) ? 2 : 1;
  });
}

// A run stopped on the coarse side of either stage's switch and resumed from its checkpoint
// ends with the models of an uninterrupted one.
TEST(CoarseStartSolverTest, ResumedAcrossTheSwitchEqualsAnUninterruptedRun) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = testing::TinySolverScene(dir + "/scene");
  for (const int levels : {1, 2}) {
    SCOPED_TRACE(std::to_string(levels) + " levels");
    SolverOptions o = ShortRun();
    o.coarse_factor = 2;
    o.coarse_levels = levels;
    MutualBoostedSolver whole(o, scene);
    SolveSummary s;
    ASSERT_TRUE(whole.Solve(&s).ok());
    // With two levels, 10 and 3 fall on the quarter-size level, 25 and 5 on the half-size one.
    for (const auto& [stage, at] : {std::make_pair(Stage::kWarmup, 10),
                                    {Stage::kWarmup, 25},
                                    {Stage::kMutual, 3},
                                    {Stage::kMutual, 5}}) {
      struct StopAt : IterationCallback {
        MutualBoostedSolver* solver;
        Stage stage;
        int at;
        CallbackReturnType operator()(const IterationInfo&) override {
          return CallbackReturnType::kContinue;
        }
        CallbackReturnType OnIterationEnd(const MutualBoostedSolver&, Stage s, int i) override {
          if (s == stage && i == at) solver->RequestStop();
          return CallbackReturnType::kContinue;
        }
      };
      MutualBoostedSolver first(o, scene);
      StopAt stop;
      stop.solver = &first;
      stop.stage = stage;
      stop.at = at;
      first.AddCallback(&stop);
      SolveSummary s1;
      ASSERT_TRUE(first.Solve(&s1).ok());
      ASSERT_EQ(s1.termination_type, TerminationType::kInterrupted);
      const std::string ckpt = dir + "/run.ckpt";
      ASSERT_TRUE(first.SaveCheckpoint(ckpt).ok());
      MutualBoostedSolver second(o, scene);
      ASSERT_TRUE(second.LoadCheckpoint(ckpt).ok());
      SolveSummary s2;
      ASSERT_TRUE(second.Solve(&s2).ok());
      testing::ExpectSameModels(whole, second);
      // Another coarse setting does not continue it.
      SolverOptions other = o;
      other.coarse_factor = 1;
      MutualBoostedSolver third(other, scene);
      const Status refused = third.LoadCheckpoint(ckpt);
      ASSERT_FALSE(refused.ok());
      EXPECT_NE(refused.message().find(o.CoarseSetting()), std::string::npos) << refused.message();
      // Nor does another number of levels.
      SolverOptions relevelled = o;
      relevelled.coarse_levels = 3 - levels;
      MutualBoostedSolver fourth(relevelled, scene);
      EXPECT_FALSE(fourth.LoadCheckpoint(ckpt).ok());
    }
  }
}

// The auto-stop waits for full-size losses: with a range every window meets, it stops a branch
// one window after the switch instead of one window after the start.
TEST(CoarseStartSolverTest, AutoStopReadsOnlyFullSizeLosses) {
  const Scene scene = testing::TinySolverScene(testing::ScratchDir());
  SolverOptions o = ShortRun();
  o.warmup_max_iterations = 80;
  o.mutual_iterations = 0;
  o.auto_stop = true;
  o.auto_stop_window = 5;
  o.auto_stop_range = 1e9;
  SolveSummary plain, coarse;
  {
    MutualBoostedSolver solver(o, scene);
    ASSERT_TRUE(solver.Solve(&plain).ok());
  }
  o.coarse_factor = 2;
  o.coarse_fraction = 0.5;
  {
    MutualBoostedSolver solver(o, scene);
    ASSERT_TRUE(solver.Solve(&coarse).ok());
  }
  EXPECT_EQ(plain.branch(Branch::kSurfels2D).warmup_iterations, 5);
  EXPECT_EQ(coarse.branch(Branch::kSurfels2D).warmup_iterations, 45);
  EXPECT_EQ(coarse.branch(Branch::kGaussians3D).warmup_iterations, 45);
}

}  // namespace
}  // namespace mgsr
