// One branch's training, whatever its primitive: a BranchTrainer owns the model, its renderer, the
// Adam state, the density statistics and schedule, the primitive budget, the background, the
// warm-up's auto-stop and the branch's loss (one Problem per stage, from the loss table). The
// solver composes two of them (the 2DGS and the 3DGS branch) and the mutual supervision between
// them; it never touches a primitive type itself (docs/design.md).
//
// PrimitiveTrainer<P> implements it for a primitive type described by P (see SurfelPrimitive and
// GaussianPrimitive in solvers/primitive_types.h); a new primitive type is a new P, its model and
// its renderer. What P supplies:
//   using Model, Renderer, Render, RenderOptions, RenderGrad, Gradients;
//   static constexpr Branch kBranch;
//   static RenderBuffers Buffers(const Camera&, const Render&);     // what loss terms read
//   static void TakeGradients(RenderGradients* from, RenderGrad* to);  // d loss / d buffers
//   static const std::vector<float>& Radii(const Renderer&);       // > 0 where drawn, last render
//   static PrimitiveLayout Layout();  // what density strategies see of the rows
// Model: size(), Blocks(), max_sh_degree, Resize(n). Renderer: Forward(model, options, &render),
// Backward(model, options, render, render_grad, &gradients). Gradients: params (a Model: d loss /
// d parameter) and mean2d (2 per primitive: the densification statistic). RenderOptions: camera,
// sh_degree, background[3].
#pragma once

#include <algorithm>
#include <array>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/profiler.h"
#include "mgsr/core/rng.h"
#include "mgsr/core/status.h"
#include "mgsr/io/binary_stream.h"
#include "mgsr/loss/exposure_compensation.h"
#include "mgsr/loss/problem.h"
#include "mgsr/render/project_gaussians.h"
#include "solvers/adam.h"
#include "solvers/auto_stop.h"
#include "solvers/checkpoint_io.h"
#include "solvers/density_control.h"
#include "solvers/density_strategy.h"
#include "solvers/environment_background.h"
#include "solvers/exposure_model.h"
#include "solvers/learning_rates.h"
#include "solvers/loss_table.h"
#include "solvers/primitive_prior.h"
#include "solvers/solver_options.h"
#include "solvers/view_group.h"

namespace mgsr {

// "2DGS" / "3DGS", and the branch's index in per-branch arrays (2DGS 0, 3DGS 1).
const char* BranchLabel(Branch branch);
constexpr int BranchIndex(Branch branch) { return branch == Branch::kSurfels2D ? 0 : 1; }

// What a branch's training reports (SolveSummary holds one per branch).
struct BranchSummary {
  int warmup_iterations = 0;
  bool auto_stopped = false;
  double final_loss = 0;  // of its last step
  size_t primitives = 0;
  size_t pruned_by_contribution = 0;  // over the stage ends of this process (not checkpointed)
};

// A branch's settings; the same for every primitive type.
struct BranchTrainerOptions {
  BranchSchedule schedule;  // density control and opacity resets
  // Thresholds of density control; max_primitives is the branch's budget (0 = none), min_opacity
  // is taken from the schedule.
  DensityOptions density;
  // The density strategy by its DensityStrategyRegistry name, and its config.
  std::string density_strategy = "reference";
  nlohmann::json density_config;
  double extent = 1;     // the scene's extent: density control's and the position rate's scale
  float background = 0;  // the grey level the branch renders and compares on
  // The learning rates at a step, by kind of parameter; the primitive type maps its blocks onto
  // them (P::LearningRates).
  std::function<RateSchedule(int iteration)> rate_schedule;
  // The warm-up's auto-stop.
  int auto_stop_min_iteration = 15000, auto_stop_window = 100;
  double auto_stop_range = 0.01;
  // The step of the per-view colour transform behind the branch's exposure rows.
  double exposure_lr = 0, exposure_prior = 0, exposure_offset_prior = 0, exposure_mean_prior = 0;
  // A learnt background per viewing direction behind the branch's renders (instead of the grey
  // `background`), for primitive types whose render options take one (kLearntBackground).
  bool environment = false;
  EnvironmentOptions environment_options;
};

// Whether a primitive type's renders take a background image (P::kLearntBackground, with
// P::BackgroundGradient); a type without it renders on its constant background.
template <typename P, typename = void>
struct HasLearntBackground : std::false_type {};
template <typename P>
struct HasLearntBackground<P, std::void_t<decltype(P::kLearntBackground)>>
    : std::integral_constant<bool, P::kLearntBackground> {};

// Whether a primitive type can skip buffers nothing reads: P::SkipUnread(BufferSet read,
// RenderOptions*) switches outputs off, P::Provides(have, want) says whether a render made with
// `have` gives every buffer one made with `want` does. A type without them renders everything.
template <typename P, typename = void>
struct SkipsUnreadBuffers : std::false_type {};
template <typename P>
struct SkipsUnreadBuffers<P, std::void_t<decltype(P::SkipUnread(
                                 BufferSet{}, static_cast<typename P::RenderOptions*>(nullptr)))>>
    : std::true_type {};

// One view of a step's batch.
struct BatchView {
  int view = 0;
  const Camera* camera = nullptr;
};

// The loss targets of each view of a batch, asked for just before the view is rendered (the
// mutual stage renders the supervising branch's target then, into storage it reuses).
class BatchTargets {
 public:
  virtual ~BatchTargets() = default;
  virtual Targets For(int position) = 0;
};

class BranchTrainer {
 public:
  // `exposure`: the per-view colour transforms the branch's exposure rows are behind (owned by the
  // solver; the two branches may share one). `rng`: the solver's generator, which density control
  // draws from (shared so a run is one reproducible sequence). The density strategy must exist
  // (SolverOptions::Validate checks the names and configs).
  BranchTrainer(Branch branch, const BranchTrainerOptions& options, ExposureModel* exposure,
                Rng* rng);
  virtual ~BranchTrainer() = default;
  BranchTrainer(const BranchTrainer&) = delete;
  BranchTrainer& operator=(const BranchTrainer&) = delete;

  Branch branch() const { return branch_; }
  const char* name() const { return BranchLabel(branch_); }
  virtual size_t size() const = 0;
  // The SH degree renders use (the warm-up raises it on a schedule).
  void set_sh_degree(int degree) { sh_degree_ = degree; }
  ExposureModel& exposure() { return *exposure_; }
  const ExposureModel& exposure() const { return *exposure_; }

  // --- The loss: one Problem per stage, built from the loss table's rows of this branch.
  // `behind_exposure`: the row compares through the view's colour transform.
  void AddLossRow(const LossSpec& row, std::unique_ptr<LossTerm> term, bool behind_exposure);
  // A row whose term is a prior on the primitives (PriorRegistry); an error naming the row when
  // the branch's model lacks a block the prior reads.
  Status AddPriorRow(const LossSpec& row, std::unique_ptr<PrimitivePrior> prior);
  // The buffers the stage's rows active at `iteration` read (weight not 0): what a step's render
  // must produce (a primitive type may skip the rest, e.g. the 2DGS distortion).
  BufferSet StageReads(Stage stage, int iteration) const;
  // Whether a row of the stage active at `iteration` reads the neighbours' rendered depth: the
  // step then renders each neighbour of its view first (multi-view terms).
  bool StageReadsNeighbourDepth(Stage stage, int iteration) const;

  // --- Training.
  // One step on a batch of `count` views (--batch_views): this process renders its part of the
  // batch (the group's rank's, solvers/view_group.h) view by view, evaluates the stage's loss on
  // each (rows switched on by `iteration`, the view's colour transform in front) and
  // back-propagates it; the view gradients, the density strategy's per-view statistics and the
  // learnt background's gradient are summed over the batch in the batch tree's order (across the
  // group's processes too); then the views' colour transforms step with their rows' gradients,
  // Adam steps once, and density control and opacity resets run on the branch's schedule at
  // `iteration`. Returns the mean loss over the batch (LastTerms: the mean term values);
  // StepStatus() says whether the step was sound. Every process of the group must call it with
  // the same batch.
  virtual double StepBatch(Stage stage, const BatchView* views, int count, BatchTargets* targets,
                           int iteration, ViewGroup* group) = 0;
  // One view, one process: StepBatch with a batch of one.
  double Step(Stage stage, int view, const Camera& camera, int iteration, const Targets& targets);
  // OK, or why the last step must stop the run: a loss row the branch cannot feed (checked on the
  // stage's first step); NonfiniteBlock() names a parameter block whose gradient was not finite.
  const Status& StepStatus() const { return step_error_; }
  const std::string& NonfiniteBlock() const { return nonfinite_block_; }
  // The active rows of the last step: label, weight, unweighted value (and the density
  // strategy's regulariser, "density_regulariser", when it has one).
  const std::vector<Problem::TermValue>& LastTerms() const { return last_terms_; }
  // The warm-up's auto-stop: records the loss of `iteration`; true once it has flattened.
  bool UpdateAutoStop(int iteration, double loss) { return auto_stop_.Update(iteration, loss); }
  BranchSummary& summary() { return summary_; }
  const BranchSummary& summary() const { return summary_; }
  // The learnt background (options.environment), or null.
  const EnvironmentBackground* environment() const { return environment_.get(); }

  // --- Supervising the other branch.
  // Renders the view with the current parameters into a render the trainer keeps until its next
  // Hold, and returns its buffers (valid as long). Until the trainer renders again (Step, Hold,
  // RenderColor), BackpropHeld can send a gradient through this render. `needed`: the buffers
  // the caller reads (a primitive type may skip others; the rest of the returned set may be
  // empty).
  virtual RenderBuffers Hold(const Camera& camera, BufferSet needed) = 0;
  RenderBuffers Hold(const Camera& camera) { return Hold(camera, kAllBuffers); }
  // Bidirectional supervision: back-propagates d loss / d buffers of the held render (the other
  // branch's loss differentiated with respect to its target) and steps Adam at `iteration`. An
  // error when the renderer no longer holds that render's forward state.
  virtual Status BackpropHeld(RenderGradients* gradient, int iteration) = 0;
  // d (the stage's loss) / d (the targets that are the other branch's renders), at the buffers
  // `at` (what the step compared), with this iteration's weights.
  void TargetGradient(Stage stage, const RenderBuffers& at, const Targets& targets,
                      TargetGradients* gradient) const;
  // The branch's colour of a view (exposure fits).
  virtual Image RenderColor(const Camera& camera) = 0;
  // Pruning by contribution: renders every camera, sums each primitive's blend weights over all of
  // them (pixel-weights: 1 is one pixel fully covered once), and drops the primitives whose sum
  // is below `min_weight` (never all of them). Returns how many it dropped.
  virtual size_t PruneByContribution(const std::vector<Camera>& cameras, double min_weight) = 0;

  // --- Supervising the other branch with the render a step already made.
  // From the next step on, each step keeps a copy of `buffer` of the render of each view of its
  // batch: the render its loss compared, made before the step's update. The other branch's step
  // that follows may read it as its target (StepBuffer) instead of rendering this branch again
  // (Hold): the authors' code, too, renders both branches on a view before it updates either.
  void KeepStepBuffer(Buffer buffer) {
    keep_step_buffer_ = true;
    kept_buffer_ = buffer;
  }
  // Keeps none from now on and forgets those kept (StepBuffer returns null).
  void StopKeepingStepBuffer() {
    keep_step_buffer_ = false;
    for (KeptBuffer& k : kept_) k.view = -1;
  }
  // The kept buffer of batch position `position` of this branch's last step, if that step
  // rendered view `view` there; else null.
  const Image* StepBuffer(int position, int view) const;

  // --- Checkpoints: everything needed to continue exactly (model, optimiser state, density
  // statistics, auto-stop window, summary). Read checks every value and keeps what it read aside;
  // CommitRead installs it (the solver commits only once the whole file has been read).
  void Save(BinaryWriter* w) const;
  Status Read(BinaryReader* r);
  void CommitRead();

 protected:
  // The stage's loss on one render; fills `gradient`, the term values and the gradient of the
  // view's colour transform (RecordView keeps them for the batch); sets step_error_ when a row
  // cannot be fed.
  double EvaluateLoss(Stage stage, int view, int iteration, const RenderBuffers& in,
                      const Targets& targets, RenderGradients* gradient);
  // A batch's per-position values (loss, term values, colour-transform gradient): BeginBatch
  // clears them for `count` positions, RecordView keeps those of the last EvaluateLoss at
  // `position`, FinishViews sums them over the group, steps each view's colour transform in batch
  // order and returns the mean loss (the mean term values into LastTerms' rows).
  void BeginBatch(Stage stage, int count);
  void RecordView(int position, double loss);
  // With KeepStepBuffer: copies the kept buffer of the render of `view` at `position`.
  void KeepFromStep(int position, int view, const RenderBuffers& buffers);
  // With KeepStepBuffer and several processes: every process ends with the kept buffers of the
  // whole batch. A process's next step reads only those of its own part (it rendered them); the
  // exchange is for the checkpoint, which process 0 writes for a resume in any process count.
  // Sets step_error_ on a failed exchange.
  void ShareStepBuffers(const BatchView* views, int count, ViewGroup* group);
  double FinishViews(Stage stage, const BatchView* views, int count, ViewGroup* group);
  // The stage's prior rows active at `iteration`, on the current model: adds each one's gradient,
  // weighted per view for a batch of `count` views, into `gradients` (the batch's summed view
  // gradients) and returns the sum of their weighted values (what they add to the mean loss).
  double EvaluatePriors(Stage stage, int iteration, int count,
                        const std::vector<ParamBlock>& gradients);
  // After the backward passes: the density strategy's statistics (the batch's sum, or null) and
  // regulariser, Adam, then its row operations on the model's rows (BindRows).
  std::string OptimizeAndControlDensity(const std::vector<float>* statistics, int views,
                                        const std::vector<ParamBlock>& gradients, int iteration);
  // Adam's learning rates at `iteration` (a callable that allocates nothing).
  Adam::LearningRates RatesAt(int iteration) const {
    return [this, iteration](const std::string& name, int width, std::vector<float>* rates) {
      rate_table_(options_.rate_schedule(iteration), name, width, rates);
    };
  }
  // The primitive type's rate table (P::LearningRates), set by PrimitiveTrainer.
  using RateTable = void (*)(const RateSchedule&, const std::string& block, int width,
                             std::vector<float>* rates);
  RateTable rate_table_ = nullptr;
  // The model's parameter blocks, as density control and Adam see them: bound once (the blocks
  // point at the model's member vectors, which stay where they are while rows change), again
  // when a checkpoint replaced the model.
  void BindRows(std::vector<ParamBlock> params);
  // The density strategy's first look at the initial model (the derived constructor calls it).
  void BeginDensity(std::vector<ParamBlock> params);
  std::unique_ptr<PrimitiveRows> rows_;
  virtual void SaveModel(BinaryWriter* w) const = 0;
  virtual Status ReadModel(BinaryReader* r) = 0;
  virtual void CommitModel() = 0;
  // What density strategies see of the primitive type's rows.
  virtual const PrimitiveLayout& Layout() const = 0;

  const Branch branch_;
  const BranchTrainerOptions options_;
  ExposureModel* const exposure_;
  Rng* const rng_;
  int sh_degree_ = 0;
  Adam adam_;
  std::unique_ptr<DensityStrategy> density_;
  std::unique_ptr<EnvironmentBackground> environment_;  // with options.environment
  Status step_error_;                                   // of the last step
  std::string nonfinite_block_;                         // of the last step

 private:
  struct StageProblem {
    Problem problem;
    std::vector<LossSpec> rows;                            // parallel to problem.entries()
    std::vector<BufferSet> reads;                          // per row: the buffers it reads
    std::vector<ExposureCompensatedLoss*> exposure_terms;  // the rows behind the colour transform
    // Active rows when their inputs and targets were last checked against a render (rows only
    // switch on, so a change of count is a change of set).
    size_t checked_active = static_cast<size_t>(-1);
    // The rows that are priors on the primitives (evaluated on the model once per step).
    std::vector<LossSpec> prior_rows;
    std::vector<std::unique_ptr<PrimitivePrior>> priors;
  };
  // A row's weight at `iteration`: 0 before its first iteration (what EvaluateLoss sets and
  // StageReads reads).
  static double RowWeightAt(const LossSpec& row, int iteration);
  StageProblem& ProblemFor(Stage s) { return problems_[s == Stage::kWarmup ? 0 : 1]; }
  const StageProblem& ProblemFor(Stage s) const { return problems_[s == Stage::kWarmup ? 0 : 1]; }

  StageProblem problems_[2];  // warm-up, mutual
  AutoStop auto_stop_;
  BranchSummary summary_;

 protected:
  // The loss rows' values of the last evaluation, and LastTerms(): those and the regulariser,
  // written in place (stable sizes within a stage: no allocation per step).
  void SetLastTerms(double regulariser) {
    size_t n = 0;
    for (const Problem::TermValue& t : loss_terms_)
      Problem::SetTermValue(&last_terms_, n++, t.name, t.weight, t.value);
    for (size_t i = 0; i < active_priors_; ++i)
      Problem::SetTermValue(&last_terms_, n++, prior_terms_[i].name, prior_terms_[i].weight,
                            prior_terms_[i].value);
    static const std::string kRegulariser = "density_regulariser";
    if (regulariser != 0) Problem::SetTermValue(&last_terms_, n++, kRegulariser, 1.0, regulariser);
    last_terms_.resize(n);
  }

 private:
  std::vector<Problem::TermValue> loss_terms_, last_terms_;
  // The active prior rows' values of the last step (the first active_priors_ entries).
  std::vector<Problem::TermValue> prior_terms_;
  size_t active_priors_ = 0;
  std::vector<float> position_rates_;   // scratch of OptimizeAndControlDensity
  ColorTransform exposure_gradient_{};  // of the last EvaluateLoss
  // Per batch position: loss, the colour transform's gradient, the term values.
  std::vector<double> position_values_;
  size_t position_stride_ = 0;
  // KeepStepBuffer's copies, per batch position of the last step (view -1: none). Checkpointed:
  // a run stopped between the two steps of a mutual round resumes with them.
  struct KeptBuffer {
    int view = -1;
    Image image;
  };
  bool keep_step_buffer_ = false;
  Buffer kept_buffer_ = Buffer::kColor;
  std::vector<KeptBuffer> kept_;
  std::vector<double> shared_shapes_;  // ShareStepBuffers' scratch
  std::vector<float> shared_data_;
  // Read, not yet committed.
  struct Pending {
    Adam adam;
    std::vector<double> window;
    BranchSummary summary;
    std::vector<KeptBuffer> kept;
  } pending_;
};

template <typename P>
class PrimitiveTrainer : public BranchTrainer {
 public:
  using Model = typename P::Model;
  // `render_options`: the branch's render settings (camera and SH degree are set per render, the
  // background from the options).
  PrimitiveTrainer(Model initial, typename P::RenderOptions render_options,
                   const BranchTrainerOptions& options, ExposureModel* exposure, Rng* rng)
      : BranchTrainer(P::kBranch, options, exposure, rng),
        model_(std::move(initial)),
        render_options_(std::move(render_options)) {
    rate_table_ = &P::LearningRates;
    for (float& b : render_options_.background) b = options.background;
    BeginDensity(model_.Blocks());
  }

  size_t size() const override { return model_.size(); }
  const Model& model() const { return model_; }
  // For tools and tests that edit a model between runs (the optimiser state keeps its rows: change
  // values, not sizes).
  Model* mutable_model() {
    held_is_current_model_ = false;
    return &model_;
  }

  // With a learnt background, the options point at this view's background, rendered into
  // storage the trainer keeps until its next RenderOptionsFor.
  typename P::RenderOptions RenderOptionsFor(const Camera& camera) {
    return OptionsFor(camera, &render_background_);
  }

  // A render of the trained model (outputs, evaluation).
  void Render(const Camera& camera, typename P::Render* out) {
    Render(RenderOptionsFor(camera), out);
  }
  // The same with options derived from RenderOptionsFor (e.g. a cheaper variant).
  void Render(const typename P::RenderOptions& options, typename P::Render* out) {
    renderer_.Forward(model_, options, out);
    held_current_ = held_is_current_model_ = false;
  }

  double StepBatch(Stage stage, const BatchView* views, int count, BatchTargets* targets,
                   int iteration, ViewGroup* group) override {
    ProfileContext context(name());
    // Renders, gradients and the batch tree's slots are members: after the first steps have
    // sized them, a step allocates nothing.
    int begin = 0, end = count;
    BatchPart(count, group->rank(), group->size(), &begin, &end);
    BeginBatch(stage, count);
    const int statistics_width = density_->ViewStatisticsWidth(iteration);
    while (static_cast<int>(slots_.size()) < BatchTreeSlots(end - begin))
      slots_.push_back(std::make_unique<Slot>());
    BatchTreeSum(
        begin, end, 0,
        [&](int position, int slot) {
          ViewGradient(stage, views[position], position, targets->For(position), iteration,
                       statistics_width, slots_[slot].get());
        },
        [&](int dst, int src) { AddSlot(*slots_[src], slots_[dst].get()); });
    if (!step_error_.ok()) {
      SetLastTerms(0.0);
      return std::numeric_limits<double>::quiet_NaN();
    }
    Slot& sum = *slots_[0];
    if (group->size() > 1) {
      SumOverGroup(group, &sum);
      ShareStepBuffers(views, count, group);
    }
    double loss = FinishViews(stage, views, count, group);
    if (!step_error_.ok()) return loss;
    loss += EvaluatePriors(stage, iteration, count, sum.blocks);  // each prior has its scope
    nonfinite_block_ = OptimizeAndControlDensity(statistics_width > 0 ? &sum.statistics : nullptr,
                                                 count, sum.blocks, iteration);
    if constexpr (HasLearntBackground<P>::value) {
      if (environment_ != nullptr) {
        ProfileScope scope("environment");
        const std::string bad = environment_->ApplyGradient(&sum.environment);
        if (nonfinite_block_.empty()) nonfinite_block_ = bad;
      }
    }
    return loss;
  }

  using BranchTrainer::Hold;
  RenderBuffers Hold(const Camera& camera, BufferSet needed) override {
    ProfileContext context(name());
    held_options_ = OptionsFor(camera, &held_background_);
    if constexpr (SkipsUnreadBuffers<P>::value) P::SkipUnread(needed, &held_options_);
    renderer_.Forward(model_, held_options_, &held_);
    held_current_ = held_is_current_model_ = true;
    return P::Buffers(held_options_.camera, held_);
  }

  Status BackpropHeld(RenderGradients* gradient, int iteration) override {
    ProfileContext context(name());
    if (!held_current_) {
      return Status::Error(std::string(name()) +
                           " trainer: the held render's forward state is gone (the branch "
                           "rendered again since Hold)");
    }
    P::TakeGradients(gradient, &step_render_grad_);
    Slot& slot = FirstSlot();
    renderer_.Backward(model_, held_options_, held_, step_render_grad_, &slot.grads);
    Bind(&slot);
    held_is_current_model_ = false;  // the step below changes the model
    ProfileScope scope("adam");
    adam_.Step(rows_->blocks(), slot.blocks, RatesAt(iteration));
    if (BackgroundGradientInto(held_options_.camera, held_, &slot))
      environment_->ApplyGradient(&slot.environment);
    return Status::Ok();
  }

  size_t PruneByContribution(const std::vector<Camera>& cameras, double min_weight) override {
    ProfileContext context(name());
    ProfileScope scope("contribution pruning");
    std::vector<double> total(model_.size(), 0.0);
    typename P::Render r;
    for (const Camera& camera : cameras) {
      typename P::RenderOptions o = RenderOptionsFor(camera);
      o.record_contribution = true;
      renderer_.Forward(model_, o, &r);
      for (size_t i = 0; i < total.size() && i < r.contribution.size(); ++i)
        total[i] += r.contribution[i];
    }
    held_current_ = held_is_current_model_ = false;
    std::vector<uint8_t> keep(total.size(), 1);
    size_t dropped = 0;
    for (size_t i = 0; i < total.size(); ++i) {
      if (total[i] < min_weight) {
        keep[i] = 0;
        ++dropped;
      }
    }
    if (dropped == 0 || dropped == total.size()) return 0;
    rows_->KeepRows(keep);
    summary().pruned_by_contribution += dropped;
    return dropped;
  }

  Image RenderColor(const Camera& camera) override {
    typename P::Render r;
    Render(camera, &r);
    return *P::Buffers(camera, r).Get(Buffer::kColor);
  }

 protected:
  void SaveModel(BinaryWriter* w) const override {
    WriteModelBlocks(w, model_.max_sh_degree, const_cast<Model&>(model_).Blocks());
  }
  Status ReadModel(BinaryReader* r) override { return ReadModelBlocks(r, &pending_model_); }
  void CommitModel() override {
    model_ = std::move(pending_model_);
    pending_model_ = Model();
    held_current_ = held_is_current_model_ = false;
    BindRows(model_.Blocks());
    for (std::unique_ptr<Slot>& slot : slots_) slot->blocks.clear();
  }
  const PrimitiveLayout& Layout() const override {
    static const PrimitiveLayout layout = P::Layout();
    return layout;
  }

 private:
  // Whether the held render gives every buffer the step's options ask for.
  bool HeldProvidesStep() const {
    if constexpr (SkipsUnreadBuffers<P>::value) {
      return P::Provides(held_options_, step_options_);
    } else {
      return true;
    }
  }

  // Renders the depth of every neighbour of `targets` and points the targets at it.
  void RenderNeighbourDepth(Targets* targets) {
    ProfileScope scope("neighbour depth");
    for (int k = 0; k < targets->num_neighbours; ++k) {
      const Camera& camera = *targets->neighbours[k].camera;
      typename P::RenderOptions o = OptionsFor(camera, &neighbour_background_);
      if constexpr (SkipsUnreadBuffers<P>::value)
        P::SkipUnread(BufferBit(Buffer::kDepth) | BufferBit(Buffer::kAlpha), &o);
      renderer_.Forward(model_, o, &neighbour_renders_[k]);
      targets->neighbours[k].depth = P::Buffers(camera, neighbour_renders_[k]).Get(Buffer::kDepth);
    }
    held_current_ = held_is_current_model_ = false;
  }

  typename P::RenderOptions OptionsFor(const Camera& camera, Image* background) {
    typename P::RenderOptions o = render_options_;
    o.camera = camera;
    o.sh_degree = sh_degree_;
    if constexpr (HasLearntBackground<P>::value) {
      if (environment_ != nullptr) {
        ProfileScope scope("environment");
        environment_->Render(camera, background);
        o.background_image = background;
      }
    }
    return o;
  }
  // A slot of the batch tree: one view's (or a subtree's summed) parameter gradients, density
  // statistics and background gradient. Behind pointers: `blocks` point into `grads`.
  struct Slot {
    typename P::Gradients grads;
    std::vector<ParamBlock> blocks;  // grads.params' blocks, bound after its first backward pass
    std::vector<float> statistics, environment;
  };
  Slot& FirstSlot() {
    if (slots_.empty()) slots_.push_back(std::make_unique<Slot>());
    return *slots_[0];
  }
  // Blocks are bound once the gradients have the model's layout (its SH width).
  static void Bind(Slot* slot) {
    if (slot->blocks.empty()) slot->blocks = slot->grads.params.Blocks();
  }

  // One leaf of the batch tree: view `v` at `position`, rendered, its loss evaluated and recorded
  // and differentiated into `slot`.
  void ViewGradient(Stage stage, const BatchView& v, int position, const Targets& targets,
                    int iteration, int statistics_width, Slot* slot) {
    if (!step_error_.ok()) return;  // an earlier view found a row the branch cannot feed
    const Camera& camera = *v.camera;
    // Multi-view rows that read the neighbours' depth: each neighbour rendered with the current
    // parameters, before this view's forward (whose state the backward needs).
    Targets step_targets = targets;
    if (step_targets.num_neighbours > 0 && StageReadsNeighbourDepth(stage, iteration))
      RenderNeighbourDepth(&step_targets);
    step_options_ = OptionsFor(camera, &step_background_);
    if constexpr (SkipsUnreadBuffers<P>::value)
      P::SkipUnread(StageReads(stage, iteration), &step_options_);
    // A mutual iteration's teacher render is often this very render: the branch supervised the
    // other one on this view and has not changed since (joint mode, 3DGS). Then the renderer
    // still holds its forward state and the step reuses it (the same bytes a new forward gives).
    const bool reuse = held_current_ && held_is_current_model_ &&
                       held_options_.sh_degree == step_options_.sh_degree &&
                       held_options_.camera == camera && HeldProvidesStep();
    if (!reuse) renderer_.Forward(model_, step_options_, &step_render_);
    const typename P::Render& render = reuse ? held_ : step_render_;
    held_current_ = held_is_current_model_ = false;
    const RenderBuffers buffers = P::Buffers(camera, render);
    KeepFromStep(position, v.view, buffers);
    const double loss =
        EvaluateLoss(stage, v.view, iteration, buffers, step_targets, &step_buffer_grad_);
    if (!step_error_.ok()) return;
    RecordView(position, loss);
    P::TakeGradients(&step_buffer_grad_, &step_render_grad_);
    renderer_.Backward(model_, step_options_, render, step_render_grad_, &slot->grads);
    Bind(slot);
    if (statistics_width > 0) {
      ProfileScope scope("density control");
      slot->statistics.resize(static_cast<size_t>(statistics_width) * model_.size());
      DensityView view;
      view.iteration = iteration;
      view.camera = &camera;
      view.mean2d = &slot->grads.mean2d;
      view.radii = &P::Radii(renderer_);
      density_->ViewStatistics(view, slot->statistics.data());
    }
    BackgroundGradientInto(camera, render, slot);
  }

  // The learnt background's gradient from the last backward pass (through `render`, seen from
  // `camera`) into slot->environment; false when the branch learns no background.
  bool BackgroundGradientInto(const Camera& camera, const typename P::Render& render, Slot* slot) {
    if constexpr (HasLearntBackground<P>::value) {
      if (environment_ != nullptr) {
        ProfileScope scope("environment");
        P::BackgroundGradient(render, step_render_grad_, &background_grad_);
        slot->environment.assign(environment_->map().texels.size(), 0.0f);
        environment_->AddGradient(camera, background_grad_, &slot->environment);
        return true;
      }
    }
    (void)camera;
    (void)render;
    (void)slot;
    return false;
  }

  // dst += src, every array element by element.
  static void AddSlot(const Slot& src, Slot* dst) {
    ProfileScope scope("batch sum");
    for (size_t b = 0; b < dst->blocks.size(); ++b)
      AddInto(*src.blocks[b].data, dst->blocks[b].data);
    AddInto(src.statistics, &dst->statistics);
    AddInto(src.environment, &dst->environment);
  }
  static void AddInto(const std::vector<float>& src, std::vector<float>* dst) {
    float* d = dst->data();
    const float* s = src.data();
    const size_t n = std::min(src.size(), dst->size());
    for (size_t i = 0; i < n; ++i) d[i] += s[i];
  }
  // The processes' parts of the batch, summed (the batch tree's upper levels).
  void SumOverGroup(ViewGroup* group, Slot* sum) {
    ProfileScope scope("batch sum");
    for (const ParamBlock& b : sum->blocks) {
      const Status s = group->SumTree(b.data->data(), b.data->size());
      if (!s.ok()) step_error_ = s;
    }
    for (std::vector<float>* v : {&sum->statistics, &sum->environment}) {
      const Status s = group->SumTree(v->data(), v->size());
      if (!s.ok()) step_error_ = s;
    }
  }

  Model model_, pending_model_;
  typename P::Renderer renderer_;
  typename P::RenderOptions render_options_, held_options_, step_options_;
  typename P::Render held_, step_render_;
  RenderGradients step_buffer_grad_;
  typename P::RenderGrad step_render_grad_;
  std::vector<std::unique_ptr<Slot>> slots_;  // the batch tree's; slot 0 holds the sum
  // The learnt background of the step's, the held and other renders, and its gradient.
  Image step_background_, held_background_, render_background_, background_grad_;
  Image neighbour_background_;
  std::array<typename P::Render, kMaxNeighbours> neighbour_renders_;
  // held_current_: the renderer still holds the forward state of held_ (BackpropHeld may run);
  // held_is_current_model_: and the model has not changed since (a step may reuse held_).
  bool held_current_ = false;
  bool held_is_current_model_ = false;
};

}  // namespace mgsr
