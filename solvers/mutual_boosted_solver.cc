#include "solvers/mutual_boosted_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "mgsr/core/timer.h"
#include "mgsr/io/view_neighbours.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/model/init_from_points.h"
#include "solvers/exposure_fit.h"
#include "solvers/step_rates.h"

namespace mgsr {
namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// What the mutual stage hands a learning branch from the supervising one (method.md 1.5): the
// buffer, the target it fills, and whether pixels outside the mask are forced to the learner's
// background (the transmitted colour is; the depth is not).
struct MutualSupervision {
  Buffer buffer;
  OtherBranchTarget target;
  bool background_outside_mask;
};

MutualSupervision SupervisionFor(Branch learner) {
  if (learner == Branch::kSurfels2D)
    return {Buffer::kTransmitted, OtherBranchTarget::kTransmitted, true};
  return {Buffer::kDepth, OtherBranchTarget::kDepth, false};
}

// Keeps the strongest of the callbacks' requests: abort over terminate over continue.
void Request(CallbackReturnType r, CallbackReturnType* kept) {
  if (r == CallbackReturnType::kAbort || *kept == CallbackReturnType::kAbort) {
    *kept = CallbackReturnType::kAbort;
  } else if (r == CallbackReturnType::kTerminateSuccessfully) {
    *kept = r;
  }
}

}  // namespace

const char* TerminationTypeName(TerminationType type) {
  switch (type) {
    case TerminationType::kNotRun:
      return "not run";
    case TerminationType::kFinished:
      return "finished";
    case TerminationType::kInterrupted:
      return "interrupted";
    case TerminationType::kUserSuccess:
      return "ended by a callback";
    case TerminationType::kUserAbort:
      return "aborted by a callback";
    case TerminationType::kFailure:
      return "failed";
  }
  return "?";
}

std::string SolveSummary::FullReport() const {
  std::ostringstream s;
  s << "MGSR solve: " << TerminationTypeName(termination_type)
    << (message.empty() ? "" : " (" + message + ")") << "\n";
  for (Branch b : {Branch::kSurfels2D, Branch::kGaussians3D}) {
    const BranchSummary& x = branch(b);
    s << "  warm-up " << BranchLabel(b) << "   " << x.warmup_iterations << " iterations"
      << (x.auto_stopped ? ", auto-stopped" : "") << ", final loss " << x.final_loss << "\n";
  }
  s << "  mutual         " << mutual_iterations << " iterations\n"
    << "  time           warm-up " << warmup_seconds << " s, mutual " << mutual_seconds
    << " s (exposure fit " << exposure_fit_seconds << " s)\n"
    << "  primitives     " << branch(Branch::kSurfels2D).primitives << " surfels, "
    << branch(Branch::kGaussians3D).primitives << " Gaussians\n";
  return s.str();
}

std::string SolveSummary::BriefReport() const {
  std::ostringstream s;
  s << "warm-up:";
  for (Branch b : {Branch::kSurfels2D, Branch::kGaussians3D}) {
    s << (b == Branch::kSurfels2D ? " " : ", ") << BranchLabel(b) << " "
      << branch(b).warmup_iterations << " it" << (branch(b).auto_stopped ? " (auto-stop)" : "");
  }
  s << ", " << warmup_seconds << " s; mutual: " << mutual_iterations << " it, " << mutual_seconds
    << " s; " << branch(Branch::kSurfels2D).primitives << " surfels, "
    << branch(Branch::kGaussians3D).primitives << " Gaussians";
  return s.str();
}

MutualBoostedSolver::MutualBoostedSolver(const SolverOptions& options, const Scene& scene)
    : options_(options), scene_(scene), rng_(options.seed) {
  train_ = scene.TrainIndices();
  static_assert(BranchIndex(Branch::kSurfels2D) == 0 && BranchIndex(Branch::kGaussians3D) == 1,
                "ViewLevel keeps the 2DGS branch's photos first");
  levels_.push_back(ViewLevel::FullSize(scene, options.background_2d, options.background_3d));
  // Each coarse level straight from the full size (not from the next finer level): every pixel
  // the exact mean of its block.
  for (int k = 1; options.coarse_factor > 1 && k <= options.coarse_levels; ++k)
    levels_.push_back(ViewLevel::Downscaled(levels_[0], options.CoarseLevelFactor(k)));
  // Initial points: a seeded subset when there are more than the options allow.
  std::vector<Eigen::Vector3f> points = scene.points, colors = scene.point_colors;
  if (points.size() > options.max_init_points) {
    std::vector<size_t> order(points.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    for (size_t i = 0; i < options.max_init_points; ++i)
      std::swap(order[i], order[i + rng_.UniformInt(order.size() - i)]);
    std::vector<Eigen::Vector3f> p, c;
    for (size_t i = 0; i < options.max_init_points; ++i) {
      p.push_back(points[order[i]]);
      c.push_back(colors[order[i]]);
    }
    points.swap(p);
    colors.swap(c);
  }
  GaussianModel gaussians;
  SurfelModel surfels;
  InitGaussiansFromPoints(points, colors, options.sh_degree, &gaussians);
  if (options.spread_initial_surfels)
    SpreadPointsOverTheirSurfaces(options.max_surfels, options.seed + 2, &points, &colors);
  InitSurfelsFromPoints(points, colors, options.sh_degree, options.seed + 1, &surfels,
                        options.surfel_orientation_from_points ? SurfelOrientation::kNeighbourhood
                                                               : SurfelOrientation::kRandom);
  if (!options.reflection) {
    // Plain 3DGS: no reflected layer (sigmoid(-30) ~ 1e-13), and its blocks never learn.
    std::fill(gaussians.ref_opacity_logits.begin(), gaussians.ref_opacity_logits.end(), -30.0f);
  }
  for (ExposureModel& e : exposures_)
    e.Reset(static_cast<int>(scene.views.size()), options.exposure, train_);

  // What both branches share; then each branch's schedule, budget and background.
  BranchTrainerOptions common;
  common.density.grad_threshold = options.densify_grad_threshold;
  common.density.percent_dense = options.percent_dense;
  common.density_strategy = options.density;
  common.density_config = options.density_config;
  common.extent = scene.extent;
  const SolverOptions* o = &options_;
  const double extent = scene.extent;
  common.auto_stop_min_iteration = options.warmup_min_iterations;
  common.auto_stop_window = options.auto_stop_window;
  common.auto_stop_range = options.auto_stop_range;
  common.exposure_lr = options.exposure_lr;
  common.exposure_prior = options.exposure_prior;
  common.exposure_offset_prior = options.exposure_offset_prior;
  common.exposure_mean_prior = options.exposure_mean_prior;
  common.environment = options.environment;

  // Each branch's rates: its own position decay (SolverOptions::PositionDecaySteps).
  const auto rates_of = [o, extent](Branch branch) {
    return [o, extent, branch](int it) { return RatesAtStep(*o, branch, it, extent); };
  };
  BranchTrainerOptions o2 = common;
  o2.rate_schedule = rates_of(Branch::kSurfels2D);
  o2.schedule = options.schedule_2d;
  o2.density.max_primitives = options.max_surfels;
  o2.background = options.background_2d;
  SurfelRenderOptions r2;
  r2.low_pass = options.surfel_area_preserving_low_pass ? SurfelLowPass::kAreaPreserving
                                                        : SurfelLowPass::kReference;
  r2.filter_sigma = options.surfel_filter_sigma;
  ExposureModel* e2 = &exposures_[BranchIndex(options.exposure_per_branch ? Branch::kSurfels2D
                                                                          : Branch::kGaussians3D)];
  surfels_ = std::make_unique<SurfelTrainer>(std::move(surfels), r2, o2, e2, &rng_);

  BranchTrainerOptions o3 = common;
  o3.rate_schedule = rates_of(Branch::kGaussians3D);
  o3.schedule = options.schedule_3d;
  o3.density.max_primitives = options.max_gaussians;
  o3.background = options.background_3d;
  gaussians_ =
      std::make_unique<GaussianTrainer>(std::move(gaussians), GaussianRenderOptions(), o3,
                                        &exposures_[BranchIndex(Branch::kGaussians3D)], &rng_);
  trainers_[BranchIndex(Branch::kSurfels2D)] = surfels_.get();
  trainers_[BranchIndex(Branch::kGaussians3D)] = gaussians_.get();
}

Status MutualBoostedSolver::BuildProblems() {
  if (problems_built_) return Status::Ok();
  for (const LossSpec& row : options_.LossTable()) {
    Status status;
    if (PriorRegistry::Get().Has(row.term)) {
      std::unique_ptr<PrimitivePrior> prior =
          PriorRegistry::Get().Create(row.term, row.config, &status);
      if (prior == nullptr) return status.WithContext("loss row " + LossSpecId(row) + ": ");
      MGSR_RETURN_IF_ERROR(trainer(row.branch).AddPriorRow(row, std::move(prior)));
      continue;
    }
    std::unique_ptr<LossTerm> term = LossRegistry::Get().Create(row.term, row.config, &status);
    if (term == nullptr) return status.WithContext("loss row " + LossSpecId(row) + ": ");
    if (term->ReadsNeighbours() && row.weight != 0) PrepareNeighbours(row.branch);
    trainer(row.branch)
        .AddLossRow(row, std::move(term), row.exposure && options_.exposure != ExposureMode::kOff);
  }
  problems_built_ = true;
  return Status::Ok();
}

void MutualBoostedSolver::SetShDegree(int degree) {
  sh_degree_ = degree;
  for (BranchTrainer* t : trainers_) t->set_sh_degree(degree);
}

void MutualBoostedSolver::FitExposures() {
  ExposureFitOptions fo;
  fo.mode = options_.exposure;
  fo.offset_prior = options_.exposure_offset_prior;
  for (int view : train_) {
    const Image* mask = views().mask(view);
    for (Branch b : {Branch::kGaussians3D, Branch::kSurfels2D}) {
      // A branch fits the transforms it owns (a shared model is the 3DGS branch's).
      BranchTrainer& t = trainer(b);
      if (&t.exposure() != &exposures_[BranchIndex(b)]) continue;
      ColorTransform p;
      if (FitColorTransform(t.RenderColor(views().camera(view)),
                            views().photo(view, BranchIndex(b)), mask, fo, &p)
              .ok())
        exposures_[BranchIndex(b)].SetTransform(view, p);
    }
  }
}

void MutualBoostedSolver::NextBatch() {
  batch_.resize(static_cast<size_t>(std::max(1, options_.batch_views)));
  for (BatchView& b : batch_) {
    b.view = NextView();
    b.camera = &views().camera(b.view);
  }
}

void MutualBoostedSolver::ReturnBatch() {
  for (auto b = batch_.rbegin(); b != batch_.rend(); ++b) view_stack_.push_back(b->view);
}

int MutualBoostedSolver::NextView() {
  // A shuffled stack of the training views, refilled when empty (method.md 1.3).
  if (view_stack_.empty()) {
    view_stack_ = train_;
    for (size_t i = view_stack_.size(); i > 1; --i)
      std::swap(view_stack_[i - 1], view_stack_[rng_.UniformInt(i)]);
  }
  const int v = view_stack_.back();
  view_stack_.pop_back();
  return v;
}

void MutualBoostedSolver::Notify(Stage stage, int iteration, const BranchTrainer& t, double loss) {
  // One per branch, assigned in place: its term list and labels keep their storage between steps.
  IterationInfo& info = iteration_info_[BranchIndex(t.branch())];
  info.stage = stage;
  info.iteration = iteration;
  info.branch = t.branch();
  info.loss = loss;
  info.num_gaussians = gaussians_->size();
  info.num_surfels = surfels_->size();
  info.seconds = Now() - start_time_;
  info.terms = t.LastTerms();
  // The caller's work (progress lines, diagnostics such as the depth check after the warm-up),
  // not the step's: its own profile row, as at the end of the iteration.
  ProfileScope scope("callbacks");
  for (IterationCallback* c : callbacks_) Request((*c)(info), &callback_request_);
}

void MutualBoostedSolver::NotifyIterationEnd(Stage stage, int iteration) {
  for (IterationCallback* c : callbacks_)
    Request(c->OnIterationEnd(*this, stage, iteration), &callback_request_);
}

void MutualBoostedSolver::PrepareNeighbours(Branch branch) {
  if (neighbours_.empty()) {
    NeighbourOptions no;
    no.count = std::min(options_.multiview_neighbours, kMaxNeighbours);
    neighbours_ = SelectNeighbours(scene_, no);
  }
  for (ViewLevel& level : levels_) level.MakeGrays(BranchIndex(branch));
}

Targets MutualBoostedSolver::LossTargets(Branch branch, int view, const Image* other) const {
  const ViewLevel& level = views();
  const int b = BranchIndex(branch);
  Targets t;
  t.mask = level.mask(view);
  t.image = &level.photo(view, b);
  if (level.has_grays(b)) {
    t.gray = &level.gray(view, b);
    for (int u : neighbours_[view]) {
      if (t.num_neighbours == kMaxNeighbours) break;
      NeighbourView& n = t.neighbours[t.num_neighbours++];
      n.camera = &level.camera(u);
      n.gray = &level.gray(u, b);
    }
  }
  if (branch == Branch::kSurfels2D) {
    t.transmitted = other;
  } else {
    t.other_depth = other;
  }
  return t;
}

Status MutualBoostedSolver::MutualStep(BranchTrainer* learner, BranchTrainer* teacher, int it,
                                       int schedule_it) {
  // The teacher's render of each view of the batch, a constant target (method.md 1.5): the one
  // its own step just made of that view if it kept it, else rendered just before the learner
  // renders that view; copied into storage kept between iterations.
  struct TeacherTargets : BatchTargets {
    MutualBoostedSolver* solver;
    BranchTrainer* learner;
    BranchTrainer* teacher;
    Targets For(int position) override {
      const int view = solver->batch_[position].view;
      const ViewLevel& level = solver->views();
      const Image* mask = level.mask(view);
      const MutualSupervision sup = SupervisionFor(learner->branch());
      const float background = learner->branch() == Branch::kSurfels2D
                                   ? solver->options_.background_2d
                                   : solver->options_.background_3d;
      Image& target = solver->mutual_target_;
      {
        // The solver's work, not the learner's (this runs inside the learner's step).
        ProfileContext solver_context("");
        ProfileScope scope("mutual targets");
        const Image* kept = teacher->StepBuffer(position, view);
        target = kept != nullptr
                     ? *kept
                     : *teacher->Hold(level.camera(view), BufferBit(sup.buffer)).Get(sup.buffer);
        if (sup.background_outside_mask && mask != nullptr)
          CompositeOverMask(*mask, background, &target);
      }
      return solver->LossTargets(learner->branch(), view, &target);
    }
  } targets;
  targets.solver = this;
  targets.learner = learner;
  targets.teacher = teacher;
  const int count = static_cast<int>(batch_.size());
  BranchSummary& sum = learner->summary();
  if (!options_.bidirectional) {
    sum.final_loss =
        learner->StepBatch(Stage::kMutual, batch_.data(), count, &targets, schedule_it, group_);
    MGSR_RETURN_IF_ERROR(CheckFinite(*learner, it, sum.final_loss));
    Notify(Stage::kMutual, it, *learner, sum.final_loss);
    return Status::Ok();
  }
  // Bidirectional (one view per step, one process: SolverOptions::Validate): the learner's render
  // the loss compares, before its step.
  const Camera& camera = views().camera(batch_[0].view);
  const Image* mask = views().mask(batch_[0].view);
  const MutualSupervision sup = SupervisionFor(learner->branch());
  const RenderBuffers before = learner->Hold(camera);
  sum.final_loss =
      learner->StepBatch(Stage::kMutual, batch_.data(), 1, &targets, schedule_it, group_);
  MGSR_RETURN_IF_ERROR(CheckFinite(*learner, it, sum.final_loss));
  // d L_learner / d target from the rows that differentiate it, at the render the loss compared;
  // pixels forced to the background are constants. The teacher's renderer still holds the
  // target's forward state (the learner's step does not use it).
  const Targets t = LossTargets(learner->branch(), batch_[0].view, &mutual_target_);
  TargetGradients d;
  learner->TargetGradient(Stage::kMutual, before, t, &d);
  Image g =
      std::move(sup.target == OtherBranchTarget::kTransmitted ? d.transmitted : d.other_depth);
  if (!g.empty()) {
    // The composite's derivative: the mask (0 outside, where the target is a constant).
    if (sup.background_outside_mask && mask != nullptr) CompositeOverMask(*mask, 0.0f, &g);
    RenderGradients into;
    into.images[static_cast<int>(sup.buffer)] = std::move(g);
    MGSR_RETURN_IF_ERROR(teacher->BackpropHeld(&into, it));
  }
  Notify(Stage::kMutual, it, *learner, sum.final_loss);
  return Status::Ok();
}

Status MutualBoostedSolver::CheckFinite(const BranchTrainer& t, int iteration, double loss) const {
  if (!t.StepStatus().ok()) return t.StepStatus();
  const std::string& block = t.NonfiniteBlock();
  if (std::isfinite(loss) && block.empty()) return Status::Ok();
  const std::string where = std::string(t.name()) + " " +
                            (stage_ == Stage::kWarmup ? "warm-up" : "mutual") + " iteration " +
                            std::to_string(iteration);
  if (!block.empty()) {
    return Status::Error("non-finite gradient of parameter block '" + block + "' at " + where +
                         " (loss " + std::to_string(loss) +
                         "); stopped, the last checkpoint is the last good state");
  }
  return Status::Error("non-finite loss (" + std::to_string(loss) + ") at " + where +
                       "; stopped, the last checkpoint is the last good state");
}

Status MutualBoostedSolver::Solve(SolveSummary* summary) {
  summary_.message.clear();
  summary_.profile.clear();
  Profiler::Take();  // what was recorded before (loading, initialisation) is not the solve's
  profile_iterations_ = 0;
  profile_timer_.Restart();
  const Status s = Run();
  CloseStageProfile(stage_);
  if (!s.ok()) {
    if (summary_.termination_type != TerminationType::kUserAbort)
      summary_.termination_type = TerminationType::kFailure;
    summary_.message = s.message();
  }
  for (const BranchTrainer* t : trainers_) {
    BranchSummary& b = summary_.branches[BranchIndex(t->branch())];
    b = t->summary();
    b.primitives = t->size();
  }
  *summary = summary_;
  return s;
}

void MutualBoostedSolver::CloseStageProfile(Stage stage) {
  if (!Profiler::Enabled()) return;
  StageProfile p;
  p.stage = stage;
  p.iterations = profile_iterations_;
  p.seconds = profile_timer_.ElapsedSeconds();
  p.entries = Profiler::Take();
  if (p.iterations > 0) summary_.profile.push_back(std::move(p));
  profile_iterations_ = 0;
  profile_timer_.Restart();
}

bool MutualBoostedSolver::EndIteration(Stage stage, int iteration, bool last, Status* status) {
  ++profile_iterations_;
  {
    ProfileScope scope("callbacks");
    NotifyIterationEnd(stage, iteration);
  }
  // Built only when the run ends here (an iteration allocates nothing otherwise).
  const auto where = [&] {
    return std::string(stage == Stage::kWarmup ? "warm-up" : "mutual") + " iteration " +
           std::to_string(iteration);
  };
  CallbackReturnType request = callback_request_;
  callback_request_ = CallbackReturnType::kContinue;
  if (group_->size() > 1) {
    // Every process ends where one ends: the strongest request of any process (its callbacks or
    // a stop request), agreed on.
    int code = request == CallbackReturnType::kAbort                   ? 3
               : request == CallbackReturnType::kTerminateSuccessfully ? 2
               : stop_requested_                                       ? 1
                                                                       : 0;
    const Status agreed = group_->Max(&code);
    if (!agreed.ok()) {
      summary_.termination_type = TerminationType::kFailure;
      *status = agreed;
      return true;
    }
    request = code == 3   ? CallbackReturnType::kAbort
              : code == 2 ? CallbackReturnType::kTerminateSuccessfully
                          : CallbackReturnType::kContinue;
    if (code == 1) stop_requested_ = 1;
  }
  if (request == CallbackReturnType::kAbort) {
    summary_.termination_type = TerminationType::kUserAbort;
    *status = Status::Error("aborted by an iteration callback after " + where());
    return true;
  }
  if (request == CallbackReturnType::kTerminateSuccessfully) {
    finished_ = true;
    summary_.termination_type = TerminationType::kUserSuccess;
    summary_.message = "after " + where();
    *status = Status::Ok();
    return true;
  }
  if (stop_requested_ && !last) {
    summary_.termination_type = TerminationType::kInterrupted;
    summary_.message = "after " + where();
    *status = Status::Ok();
    return true;
  }
  return false;
}

Status MutualBoostedSolver::Run() {
  callback_request_ = CallbackReturnType::kContinue;
  if (finished_) {
    // A finished run (a checkpoint of one) stays finished, also when a callback ended it early.
    if (summary_.termination_type == TerminationType::kNotRun)
      summary_.termination_type = TerminationType::kFinished;
    SetShDegree(options_.sh_degree);
    return Status::Ok();
  }
  MGSR_RETURN_IF_ERROR(options_.Validate());
  MGSR_RETURN_IF_ERROR(BuildProblems());
  if (train_.empty()) return Status::Error("the scene has no training views");
  if (gaussians_->size() == 0) return Status::Error("the scene has no initial points");
  stop_requested_ = 0;
  start_time_ = Now() - summary_.warmup_seconds - summary_.mutual_seconds;
  const SolverOptions& o = options_;
  SolveSummary& sum = summary_;
  Status ended;

  // Warm-up: the branches step in turn (2DGS first); each stops on its own.
  Timer warmup;
  const double warmup_before = sum.warmup_seconds;
  while (stage_ == Stage::kWarmup) {
    std::array<bool, 2> done{};
    for (const BranchTrainer* t : trainers_) {
      const BranchSummary& b = t->summary();
      done[BranchIndex(t->branch())] =
          !Trains(t->branch()) || b.auto_stopped || b.warmup_iterations >= o.warmup_max_iterations;
    }
    if (done[0] && done[1]) {
      PruneByContribution();
      CloseStageProfile(Stage::kWarmup);
      // The mutual stage's first round's size, for the fit too.
      UseLevel(o.CoarseLevelAt(Stage::kMutual, 1));
      if (o.exposure != ExposureMode::kOff && o.exposure_fit_at_mutual && o.train_2d &&
          o.train_3d) {
        Timer fit;
        ProfileScope scope("exposure fit");
        SetShDegree(o.sh_degree);
        FitExposures();
        sum.exposure_fit_seconds = fit.ElapsedSeconds();
      }
      stage_ = Stage::kMutual;
      next_iteration_ = 1;
      break;
    }
    const int it = next_iteration_;
    SetShDegree(std::min(o.sh_degree, it / o.sh_interval));
    UseLevel(o.CoarseLevelAt(Stage::kWarmup, it));
    const bool coarse = level_ != 0;
    NextBatch();
    for (BranchTrainer* t : trainers_) {
      if (done[BranchIndex(t->branch())]) continue;
      // The photos of the batch's views.
      struct PhotoTargets : BatchTargets {
        const MutualBoostedSolver* solver;
        Branch branch;
        Targets For(int position) override {
          return solver->LossTargets(branch, solver->batch_[position].view, nullptr);
        }
      } targets;
      targets.solver = this;
      targets.branch = t->branch();
      BranchSummary& b = t->summary();
      b.final_loss = t->StepBatch(Stage::kWarmup, batch_.data(), static_cast<int>(batch_.size()),
                                  &targets, it, group_);
      MGSR_RETURN_IF_ERROR(CheckFinite(*t, it, b.final_loss));
      b.warmup_iterations = it;
      Notify(Stage::kWarmup, it, *t, b.final_loss);
      // A coarse step's loss is not the full-size loss the auto-stop waits to flatten.
      b.auto_stopped = o.auto_stop && !coarse && t->UpdateAutoStop(it, b.final_loss);
    }
    ++next_iteration_;
    sum.warmup_seconds = warmup_before + warmup.ElapsedSeconds();
    if (EndIteration(Stage::kWarmup, it, false, &ended)) return ended;
  }
  SetShDegree(o.sh_degree);

  // Mutual stage: the supervising branch's render is a constant target.
  Timer mutual;
  const double mutual_before = sum.mutual_seconds;
  const bool both = o.train_2d && o.train_3d;
  // Each round's 2DGS step comes first and renders the views the 3DGS step after it reads the
  // depth of: that step takes the depth from the 2DGS step's render (made before its update,
  // as in the authors' code) instead of rendering the 2DGS branch again. Not with
  // bidirectional supervision (its gradient needs a held render).
  // Past `mutual_iterations_2d` the 2DGS branch is held: it no longer steps, and each 3DGS step
  // renders it (what a kept buffer holds would be from before its last update).
  const auto steps_2d = [&o](int it) {
    return o.mutual_iterations_2d < 0 || it <= o.mutual_iterations_2d;
  };
  if (both && !o.bidirectional && steps_2d(next_iteration_))
    surfels_->KeepStepBuffer(SupervisionFor(Branch::kGaussians3D).buffer);
  while (both && next_iteration_ <= o.mutual_iterations) {
    const int it = next_iteration_;
    const bool joint = o.mutual_mode == "joint";
    if (!steps_2d(it)) surfels_->StopKeepingStepBuffer();
    UseLevel(o.CoarseLevelAt(Stage::kMutual, it));
    NextBatch();
    // In alternate mode a round (the 2DGS step, then the 3DGS step) takes one batch, as the
    // reference's iteration takes one view for both branches: the views go back on the stack for
    // the round's second step (a checkpoint between the steps keeps them). That step then reuses
    // the 3DGS render that supervised the first (the branch has not changed since): one 3DGS
    // forward less per round.
    if (!joint && it % 2 == 1) ReturnBatch();
    // The count the branch schedules (density control, opacity reset, learning rates) see. In
    // alternate mode the 2DGS branch steps on odd counts only, so it takes the count of the round
    // it opens: events on even counts then reach both branches, in the same round.
    const int schedule_it = joint ? it : it + it % 2;
    if ((joint || it % 2 == 1) && steps_2d(it))
      MGSR_RETURN_IF_ERROR(MutualStep(surfels_.get(), gaussians_.get(), it, schedule_it));
    if (joint || it % 2 == 0)
      MGSR_RETURN_IF_ERROR(MutualStep(gaussians_.get(), surfels_.get(), it, schedule_it));
    sum.mutual_iterations = it;
    ++next_iteration_;
    sum.mutual_seconds = mutual_before + mutual.ElapsedSeconds();
    if (EndIteration(Stage::kMutual, it, next_iteration_ > o.mutual_iterations, &ended))
      return ended;
  }
  if (both) PruneByContribution();  // (a single branch was pruned at the end of its warm-up)
  finished_ = true;
  sum.termination_type = TerminationType::kFinished;
  return Status::Ok();
}

void MutualBoostedSolver::PruneByContribution() {
  if (options_.prune_contribution <= 0) return;
  std::vector<Camera> cameras;
  for (int v : train_) cameras.push_back(scene_.views[v].camera);
  for (BranchTrainer* t : trainers_) {
    if (Trains(t->branch())) t->PruneByContribution(cameras, options_.prune_contribution);
  }
}

}  // namespace mgsr
