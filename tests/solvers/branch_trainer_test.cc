// The generic branch trainer with a primitive type that is neither a surfel nor a Gaussian: a stub
// whose primitives are horizontal bands of flat colour. It trains, checkpoints and supervises
// through the same code as the two real branches (solvers/branch_trainer.h), which is what a new
// primitive type would get.
#include "solvers/branch_trainer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "mgsr/loss/loss_registry.h"

namespace mgsr {
namespace {

// N bands, each one RGB colour; band k covers rows [k H / N, (k + 1) H / N) of every view.
struct BandModel {
  int max_sh_degree = 0;
  std::vector<float> colour;  // N x 3
  size_t size() const { return colour.size() / 3; }
  void Resize(size_t n) { colour.resize(3 * n); }
  std::vector<ParamBlock> Blocks() { return {{"colour", &colour, 3}}; }
};

struct BandRenderOptions {
  Camera camera;
  int sh_degree = 0;
  float background[3] = {0, 0, 0};
  bool record_contribution = false;
  bool alpha = true;  // an output a type may skip (SkippingBandPrimitive)
};

struct BandRender {
  Image color;
  Image alpha;                      // 1 everywhere, when rendered
  std::vector<float> contribution;  // empty: the stub never prunes
};

struct BandRenderGrad {
  Image color;
};

struct BandGradients {
  BandModel params;
  std::vector<float> mean2d;
};

int BandOfRow(int row, int height, size_t bands) {
  return static_cast<int>(static_cast<size_t>(row) * bands / static_cast<size_t>(height));
}

class BandRenderer {
 public:
  void Forward(const BandModel& m, const BandRenderOptions& o, BandRender* out) {
    ++forwards;
    out->alpha = Image();
    if (o.alpha) {
      ++alpha_renders;
      out->alpha = Image(o.camera.width, o.camera.height, 1);
      out->alpha.Fill(1.0f);
    }
    out->color = Image(o.camera.width, o.camera.height, 3);
    for (int y = 0; y < o.camera.height; ++y) {
      const int k = BandOfRow(y, o.camera.height, m.size());
      for (int x = 0; x < o.camera.width; ++x) {
        for (int c = 0; c < 3; ++c) out->color.at(c, y, x) = m.colour[3 * k + c];
      }
    }
    radius_.assign(m.size(), 1.0f);
  }
  void Backward(const BandModel& m, const BandRenderOptions& o, const BandRender& /*render*/,
                const BandRenderGrad& g, BandGradients* out) {
    out->params.Resize(m.size());
    std::fill(out->params.colour.begin(), out->params.colour.end(), 0.0f);
    out->mean2d.assign(2 * m.size(), 0.0f);
    if (g.color.empty()) return;
    for (int y = 0; y < o.camera.height; ++y) {
      const int k = BandOfRow(y, o.camera.height, m.size());
      for (int x = 0; x < o.camera.width; ++x) {
        for (int c = 0; c < 3; ++c) out->params.colour[3 * k + c] += g.color.at(c, y, x);
      }
    }
  }
  const std::vector<float>& radius() const { return radius_; }
  static int forwards;       // every Forward of every band renderer
  static int alpha_renders;  // those that rendered the alpha

 private:
  std::vector<float> radius_;
};

int BandRenderer::forwards = 0;
int BandRenderer::alpha_renders = 0;

// The primitive type's description for PrimitiveTrainer: no density control (a fixed band count).
struct BandPrimitive {
  using Model = BandModel;
  using Renderer = BandRenderer;
  using Render = BandRender;
  using RenderOptions = BandRenderOptions;
  using RenderGrad = BandRenderGrad;
  using Gradients = BandGradients;
  static constexpr Branch kBranch = Branch::kGaussians3D;

  static RenderBuffers Buffers(const Camera& camera, const Render& r) {
    RenderBuffers in;
    in.camera = &camera;
    in.Set(Buffer::kColor, &r.color);
    if (!r.alpha.empty()) in.Set(Buffer::kAlpha, &r.alpha);
    return in;
  }
  static void TakeGradients(RenderGradients* from, RenderGrad* to) {
    to->color = std::move(from->images[static_cast<int>(Buffer::kColor)]);
  }
  static const std::vector<float>& Radii(const Renderer& r) { return r.radius(); }
  // Every block of the stub at one rate.
  static void LearningRates(const RateSchedule&, const std::string&, int width,
                            std::vector<float>* rates) {
    rates->assign(width, 0.02f);
  }
  static PrimitiveLayout Layout() {
    PrimitiveLayout l;
    l.scale_axes = 0;
    l.opacity_blocks.clear();
    l.opacity_reset_caps.clear();
    return l;
  }
};

// A density strategy registered by the test, as a researcher's would be: it records which steps
// reach it and what it sees of the rows.
struct CountingDensity : DensityStrategy {
  static int begin_calls, before_calls, after_calls, events;
  static size_t rows_seen;
  explicit CountingDensity(const DensityContext& c) : context(c) {}
  void Begin(PrimitiveRows* rows, Rng*) override {
    ++begin_calls;
    rows_seen = rows->size();
  }
  // One statistic per primitive: 1 where drawn; the step sees it summed over its views.
  int ViewStatisticsWidth(int) const override { return 1; }
  void ViewStatistics(const DensityView& view, float* out) override {
    EXPECT_EQ(view.mean2d->size(), 2 * view.radii->size());
    for (size_t i = 0; i < view.radii->size(); ++i) out[i] = (*view.radii)[i] > 0 ? 1.0f : 0.0f;
  }
  double BeforeStep(const DensityStep& step, const PrimitiveRows& rows,
                    const std::vector<ParamBlock>& gradients) override {
    ++before_calls;
    rows_seen = rows.size();
    EXPECT_EQ(step.views, 1);
    EXPECT_EQ(step.statistics->size(), rows.size());
    for (float drawn : *step.statistics) EXPECT_TRUE(drawn == 0.0f || drawn == 1.0f);
    EXPECT_EQ(gradients.size(), rows.blocks().size());
    return 0;
  }
  DensifyResult AfterStep(const DensityStep& step, PrimitiveRows*, Rng*) override {
    ++after_calls;
    const BranchSchedule& s = context.schedule;
    if (step.iteration > s.densify_from && step.iteration < s.densify_until &&
        step.iteration % s.densify_interval == 0)
      ++events;
    return {};
  }
  void Save(BinaryWriter*) const override {}
  Status Read(BinaryReader*) override { return Status::Ok(); }
  void CommitRead() override {}
  DensityContext context;
};
int CountingDensity::begin_calls = 0;
int CountingDensity::before_calls = 0;
int CountingDensity::after_calls = 0;
int CountingDensity::events = 0;
size_t CountingDensity::rows_seen = 0;

// The same type skipping its alpha where no active loss row reads it (as the 2DGS branch skips
// its distortion).
struct SkippingBandPrimitive : BandPrimitive {
  static void SkipUnread(BufferSet read, RenderOptions* o) {
    o->alpha = (read & BufferBit(Buffer::kAlpha)) != 0;
  }
  static bool Provides(const RenderOptions& have, const RenderOptions& want) {
    return have.alpha || !want.alpha;
  }
};

using BandTrainer = PrimitiveTrainer<BandPrimitive>;

Camera SmallCamera() {
  Camera c;
  c.width = 8;
  c.height = 12;
  c.fx = c.fy = 10;
  c.cx = 4;
  c.cy = 6;
  return c;
}

// The photo: band k of 4 in grey level 0.2 + 0.2 k.
Image BandPhoto(const Camera& c) {
  Image im(c.width, c.height, 3);
  for (int y = 0; y < c.height; ++y) {
    for (int x = 0; x < c.width; ++x) {
      for (int ch = 0; ch < 3; ++ch) im.at(ch, y, x) = 0.2f + 0.2f * BandOfRow(y, c.height, 4);
    }
  }
  return im;
}

BranchTrainerOptions StubOptions() {
  BranchTrainerOptions o;
  o.schedule.densify_from = 10;
  o.schedule.densify_until = 40;
  o.schedule.densify_interval = 10;
  o.schedule.opacity_reset_interval = 25;
  o.rate_schedule = [](int) { return RateSchedule(); };
  o.auto_stop_min_iteration = 0;
  o.auto_stop_window = 10;
  o.auto_stop_range = 1e-3;
  DensityStrategyRegistry::Get().Register(
      "counting", [](const DensityContext& c, const nlohmann::json&, Status*) {
        return std::make_unique<CountingDensity>(c);
      });
  o.density_strategy = "counting";
  return o;
}

template <typename Trainer = BandTrainer>
std::unique_ptr<Trainer> MakeTrainer(ExposureModel* exposure, Rng* rng) {
  BandModel m;
  m.Resize(4);
  std::fill(m.colour.begin(), m.colour.end(), 0.5f);
  auto t =
      std::make_unique<Trainer>(std::move(m), BandRenderOptions(), StubOptions(), exposure, rng);
  LossSpec row;
  row.branch = Branch::kGaussians3D;
  row.stage = Stage::kWarmup;
  row.name = "photo_l1";
  row.term = "l1";
  row.weight = 1.0;
  Status s;
  t->AddLossRow(row, LossRegistry::Get().Create("l1", row.config, &s), false);
  EXPECT_TRUE(s.ok()) << s.message();
  return t;
}

// One view of the band photo, without exposure compensation.
struct BandView {
  BandView() {
    targets.image = &photo;
    exposure.Reset(1, ExposureMode::kOff);
  }
  const Camera camera = SmallCamera();
  const Image photo = BandPhoto(camera);
  Targets targets;
  ExposureModel exposure;
};

// Adds a warm-up row of the edge-aware TV of `buffer` (guided by the photo), on from
// `first_iteration`.
void AddTvRow(BranchTrainer* t, const std::string& name, const std::string& buffer,
              int first_iteration = 0) {
  LossSpec row;
  row.branch = Branch::kGaussians3D;
  row.stage = Stage::kWarmup;
  row.name = name;
  row.term = "tv";
  row.config = {{"buffer", buffer}, {"guide", "image"}};
  row.weight = 1.0;
  row.first_iteration = first_iteration;
  Status s;
  t->AddLossRow(row, LossRegistry::Get().Create("tv", row.config, &s), false);
  ASSERT_TRUE(s.ok()) << s.message();
}

TEST(BranchTrainerTest, AStubPrimitiveTrainsChecksPointsAndSupervisesThroughTheGenericTrainer) {
  CountingDensity::begin_calls = CountingDensity::before_calls = CountingDensity::after_calls =
      CountingDensity::events = 0;
  const Camera camera = SmallCamera();
  const Image photo = BandPhoto(camera);
  Targets targets;
  targets.image = &photo;
  ExposureModel exposure;
  exposure.Reset(1, ExposureMode::kOff);
  Rng rng(7);
  std::unique_ptr<BandTrainer> t = MakeTrainer(&exposure, &rng);
  EXPECT_EQ(t->size(), 4u);
  EXPECT_STREQ(t->name(), "3DGS");

  // Training: the loss falls and every band reaches its photo's grey level; the schedule's
  // density events reach the primitive type (iterations 20 and 30; resets at 25).
  const double first = t->Step(Stage::kWarmup, 0, camera, 1, targets);
  ASSERT_TRUE(t->StepStatus().ok()) << t->StepStatus().message();
  double loss = first;
  int it = 2;
  for (; it <= 60; ++it) loss = t->Step(Stage::kWarmup, 0, camera, it, targets);
  EXPECT_GT(first, 0.1);
  EXPECT_LT(loss, 0.01 * first);
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(t->model().colour[3 * k], 0.2f + 0.2f * k, 0.02f);
  EXPECT_EQ(CountingDensity::begin_calls, 1);
  EXPECT_EQ(CountingDensity::before_calls, 60);
  EXPECT_EQ(CountingDensity::after_calls, 60);
  EXPECT_EQ(CountingDensity::events, 2);
  EXPECT_EQ(CountingDensity::rows_seen, 4u);
  ASSERT_EQ(t->LastTerms().size(), 1u);
  EXPECT_EQ(t->LastTerms()[0].name, "photo_l1");

  // Checkpoint through the generic Save/Read/CommitRead: a second trainer continues exactly.
  t->summary().warmup_iterations = 60;
  BinaryWriter w;
  t->Save(&w);
  Rng rng2(7);
  rng2.set_state(rng.state());
  std::unique_ptr<BandTrainer> u = MakeTrainer(&exposure, &rng2);
  const std::string data = w.data();
  BinaryReader r("stub.ckpt", data);
  ASSERT_TRUE(u->Read(&r).ok());
  EXPECT_TRUE(r.AtEnd());
  EXPECT_EQ(u->summary().warmup_iterations, 0);  // nothing changes before the commit
  u->CommitRead();
  EXPECT_EQ(u->summary().warmup_iterations, 60);
  for (int k = 0; k < 5; ++k, ++it) {
    EXPECT_EQ(t->Step(Stage::kWarmup, 0, camera, it, targets),
              u->Step(Stage::kWarmup, 0, camera, it, targets));
  }
  EXPECT_EQ(t->model().colour, u->model().colour);

  // A truncated checkpoint is refused naming the file.
  const std::string cut = data.substr(0, data.size() / 2);
  BinaryReader short_reader("cut.ckpt", cut);
  const Status bad = u->Read(&short_reader);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("cut.ckpt"), std::string::npos) << bad.message();

  // Supervision: a held render's buffers, a gradient sent back through it, and an error once the
  // branch has rendered again.
  const RenderBuffers held = t->Hold(camera);
  ASSERT_NE(held.Get(Buffer::kColor), nullptr);
  const float before = t->model().colour[0];
  RenderGradients g;
  g.Get(Buffer::kColor, *held.Get(Buffer::kColor)).Fill(1.0f);  // d/dc > 0: the colour falls
  ASSERT_TRUE(t->BackpropHeld(&g, it).ok());
  EXPECT_LT(t->model().colour[0], before);
  t->Step(Stage::kWarmup, 0, camera, it, targets);
  RenderGradients g2;
  g2.Get(Buffer::kColor, photo).Fill(1.0f);
  EXPECT_FALSE(t->BackpropHeld(&g2, it).ok());
}

// A step on the view the branch has just rendered as a teacher, with the model unchanged since,
// reuses that render (no second forward) and trains exactly as a step that renders afresh; any
// change in between (a step sent back through the held render, another camera, another SH
// degree) renders again.
TEST(BranchTrainerTest, AStepReusesTheHeldRenderOfTheSameViewAndModel) {
  const Camera camera = SmallCamera();
  Camera other = camera;
  other.t.x() += 0.5;
  const Image photo = BandPhoto(camera);
  Targets targets;
  targets.image = &photo;
  ExposureModel exposure;
  exposure.Reset(1, ExposureMode::kOff);
  Rng rng_a(3), rng_b(3);
  std::unique_ptr<BandTrainer> a = MakeTrainer(&exposure, &rng_a);
  std::unique_ptr<BandTrainer> b = MakeTrainer(&exposure, &rng_b);
  for (int it = 1; it <= 3; ++it) {
    a->Step(Stage::kWarmup, 0, camera, it, targets);
    b->Step(Stage::kWarmup, 0, camera, it, targets);
  }
  // Reused: one forward (the hold's) for hold + step; the same model as without the hold.
  int before = BandRenderer::forwards;
  a->Hold(camera);
  const double loss_a = a->Step(Stage::kWarmup, 0, camera, 4, targets);
  EXPECT_EQ(BandRenderer::forwards - before, 1);
  before = BandRenderer::forwards;
  const double loss_b = b->Step(Stage::kWarmup, 0, camera, 4, targets);
  EXPECT_EQ(BandRenderer::forwards - before, 1);
  EXPECT_EQ(loss_a, loss_b);
  EXPECT_EQ(a->model().colour, b->model().colour);
  // Not reused: the model changed through the held render, the camera or the SH degree differ.
  RenderGradients g;
  g.Get(Buffer::kColor, *a->Hold(camera).Get(Buffer::kColor)).Fill(1.0f);
  ASSERT_TRUE(a->BackpropHeld(&g, 5).ok());
  before = BandRenderer::forwards;
  a->Step(Stage::kWarmup, 0, camera, 6, targets);
  EXPECT_EQ(BandRenderer::forwards - before, 1);
  a->Hold(other);
  before = BandRenderer::forwards;
  a->Step(Stage::kWarmup, 0, camera, 7, targets);
  EXPECT_EQ(BandRenderer::forwards - before, 1);
  a->Hold(camera);
  a->set_sh_degree(1);
  before = BandRenderer::forwards;
  a->Step(Stage::kWarmup, 0, camera, 8, targets);
  EXPECT_EQ(BandRenderer::forwards - before, 1);
  a->set_sh_degree(0);
  a->Hold(camera);
  a->mutable_model()->colour[0] += 0.1f;
  before = BandRenderer::forwards;
  a->Step(Stage::kWarmup, 0, camera, 9, targets);
  EXPECT_EQ(BandRenderer::forwards - before, 1);
}

TEST(BranchTrainerTest, ARowTheBranchCannotFeedStopsTheStepNamingIt) {
  BandView v;
  Rng rng(1);
  std::unique_ptr<BandTrainer> t = MakeTrainer(&v.exposure, &rng);
  AddTvRow(t.get(), "depth_smooth", "depth");
  const double loss = t->Step(Stage::kWarmup, 0, v.camera, 1, v.targets);
  EXPECT_TRUE(std::isnan(loss));
  ASSERT_FALSE(t->StepStatus().ok());
  EXPECT_NE(t->StepStatus().message().find("3DGS warmup loss row"), std::string::npos)
      << t->StepStatus().message();
  EXPECT_NE(t->StepStatus().message().find("depth_smooth"), std::string::npos)
      << t->StepStatus().message();
}

// A type that can skip outputs renders only what the active rows read: a row switched on at
// iteration 3 brings its buffer back (and is checked then); a held render made without a buffer
// the step reads is not reused, one made with it is.
TEST(BranchTrainerTest, RendersSkipBuffersNoActiveRowReads) {
  BandView v;
  Rng rng(1);
  auto t = MakeTrainer<PrimitiveTrainer<SkippingBandPrimitive>>(&v.exposure, &rng);
  AddTvRow(t.get(), "alpha_smooth", "alpha", /*first_iteration=*/3);
  EXPECT_EQ(t->StageReads(Stage::kWarmup, 2), BufferBit(Buffer::kColor));
  EXPECT_EQ(t->StageReads(Stage::kWarmup, 3),
            BufferBit(Buffer::kColor) | BufferBit(Buffer::kAlpha));
  const int alpha_before = BandRenderer::alpha_renders;
  for (int it = 1; it <= 2; ++it) t->Step(Stage::kWarmup, 0, v.camera, it, v.targets);
  EXPECT_EQ(BandRenderer::alpha_renders - alpha_before, 0);
  const double loss = t->Step(Stage::kWarmup, 0, v.camera, 3, v.targets);
  ASSERT_TRUE(t->StepStatus().ok()) << t->StepStatus().message();
  EXPECT_TRUE(std::isfinite(loss));
  EXPECT_EQ(BandRenderer::alpha_renders - alpha_before, 1);
  // Held for a colour target only: the step reading the alpha renders again.
  t->Hold(v.camera, BufferBit(Buffer::kColor));
  int before = BandRenderer::forwards;
  t->Step(Stage::kWarmup, 0, v.camera, 4, v.targets);
  EXPECT_EQ(BandRenderer::forwards - before, 1);
  // Held with everything: reused.
  t->Hold(v.camera);
  before = BandRenderer::forwards;
  t->Step(Stage::kWarmup, 0, v.camera, 5, v.targets);
  EXPECT_EQ(BandRenderer::forwards - before, 0);
}

// A row switched on later is checked when it switches on: one the branch cannot feed stops that
// step, naming it (and the steps before it ran).
TEST(BranchTrainerTest, ARowSwitchedOnLaterIsCheckedThen) {
  BandView v;
  Rng rng(1);
  std::unique_ptr<BandTrainer> t = MakeTrainer(&v.exposure, &rng);
  AddTvRow(t.get(), "late_depth_smooth", "depth", /*first_iteration=*/3);
  for (int it = 1; it <= 2; ++it) {
    EXPECT_TRUE(std::isfinite(t->Step(Stage::kWarmup, 0, v.camera, it, v.targets)));
    EXPECT_TRUE(t->StepStatus().ok());
  }
  EXPECT_TRUE(std::isnan(t->Step(Stage::kWarmup, 0, v.camera, 3, v.targets)));
  ASSERT_FALSE(t->StepStatus().ok());
  EXPECT_NE(t->StepStatus().message().find("late_depth_smooth"), std::string::npos)
      << t->StepStatus().message();
}

// A prior that pulls every colour towards 0.9: the mean over entries of (c - 0.9)^2.
class PullColourPrior : public PrimitivePrior {
 public:
  Status Check(const std::vector<ParamBlock>& params) const override {
    return CheckParamBlock(params, "colour", 3);
  }
  double Evaluate(const std::vector<ParamBlock>& params, double scale,
                  const std::vector<ParamBlock>* gradients) override {
    const std::vector<float>& c = *FindParamBlock(params, "colour")->data;
    std::vector<float>* g =
        gradients != nullptr ? FindParamBlock(*gradients, "colour")->data : nullptr;
    double e = 0;
    for (size_t i = 0; i < c.size(); ++i) {
      e += (c[i] - 0.9) * (c[i] - 0.9);
      if (g != nullptr) (*g)[i] += static_cast<float>(scale * 2 * (c[i] - 0.9) / c.size());
    }
    ++evaluations;
    last_scale = scale;
    return e / c.size();
  }
  int evaluations = 0;
  double last_scale = 0;
};

class NeedsMeansPrior : public PullColourPrior {
 public:
  Status Check(const std::vector<ParamBlock>& params) const override {
    return CheckParamBlock(params, "means", 3);
  }
};

TEST(BranchTrainerTest, APriorRowPullsTheModelFromItsFirstIterationAndIsReported) {
  BandView v;
  Rng rng(7);
  std::unique_ptr<BandTrainer> t = MakeTrainer(&v.exposure, &rng);
  LossSpec row;
  row.branch = Branch::kGaussians3D;
  row.stage = Stage::kWarmup;
  row.name = "pull";
  row.term = "pull_colour";
  row.weight = 100;
  row.first_iteration = 20;
  auto owned = std::make_unique<PullColourPrior>();
  PullColourPrior* prior = owned.get();
  ASSERT_TRUE(t->AddPriorRow(row, std::move(owned)).ok());
  int it = 1;
  for (; it < 20; ++it) t->Step(Stage::kWarmup, 0, v.camera, it, v.targets);
  EXPECT_EQ(prior->evaluations, 0);
  ASSERT_EQ(t->LastTerms().size(), 1u);
  double loss = 0;
  for (; it <= 120; ++it) loss = t->Step(Stage::kWarmup, 0, v.camera, it, v.targets);
  ASSERT_TRUE(t->StepStatus().ok()) << t->StepStatus().message();
  EXPECT_EQ(prior->evaluations, 101);
  EXPECT_EQ(prior->last_scale, 100.0);  // the row's weight, once per view of the batch
  ASSERT_EQ(t->LastTerms().size(), 2u);
  EXPECT_EQ(t->LastTerms()[1].name, "pull");
  EXPECT_EQ(t->LastTerms()[1].weight, 100.0);
  // The step's loss is the photo's plus the weighted prior.
  EXPECT_NEAR(loss, t->LastTerms()[0].value + 100.0 * t->LastTerms()[1].value, 1e-9);
  // The heavy prior holds every band above its photo's grey (0.2 .. 0.8).
  for (float c : t->model().colour) EXPECT_GT(c, 0.85f);

  // A prior that reads a block the model does not have is refused, naming the row and block.
  row.name = "needs_means";
  const Status s = t->AddPriorRow(row, std::make_unique<NeedsMeansPrior>());
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("3d/warmup/needs_means"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("\"means\""), std::string::npos) << s.message();
}

}  // namespace
}  // namespace mgsr
