// MutualBoostedSolver: MGSR's optimisation (docs/design.md). Both branches warm up in turn,
// each stopping on its own when its loss flattens (auto-stop) or at a cap; then the mutual stage:
// the 2DGS branch learns from the 3DGS branch's transmitted image and the 3DGS branch from the
// 2DGS depth, each held constant while it supervises (one-way back-propagation). `alternate`
// steps one branch per iteration (the paper), `joint` both (the authors' code).
#pragma once

#include <array>
#include <csignal>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "mgsr/core/image.h"
#include "mgsr/core/profiler.h"
#include "mgsr/core/rng.h"
#include "mgsr/core/timer.h"
#include "mgsr/io/scene.h"
#include "mgsr/loss/problem.h"
#include "mgsr/model/gaussian_model.h"
#include "mgsr/model/surfel_model.h"
#include "mgsr/render/gaussian_renderer.h"
#include "mgsr/render/surfel_renderer.h"
#include "solvers/branch_trainer.h"
#include "solvers/exposure_model.h"
#include "solvers/primitive_types.h"
#include "solvers/solver_options.h"
#include "solvers/view_levels.h"

namespace mgsr {

// What an iteration callback sees (Ceres' IterationSummary).
struct IterationInfo {
  Stage stage;
  int iteration;  // within the stage
  Branch branch;
  double loss;
  size_t num_gaussians, num_surfels;
  double seconds;  // since Solve started
  // The loss table's active rows for this step: label, weight and unweighted value (the loss is
  // the sum of weight x value).
  std::vector<Problem::TermValue> terms;
};

class MutualBoostedSolver;

// What a callback asks of the solver (Ceres' CallbackReturnType). Anything but kContinue takes
// effect at the end of the current iteration (after every branch of it has stepped), so the state
// Solve returns with is always one a checkpoint can hold and a later Solve can continue from.
enum class CallbackReturnType {
  kContinue,
  kAbort,                  // Solve returns an error (termination kUserAbort)
  kTerminateSuccessfully,  // Solve returns the run as finished (termination kUserSuccess)
};

class IterationCallback {
 public:
  virtual ~IterationCallback() = default;
  // After each branch's step.
  virtual CallbackReturnType operator()(const IterationInfo& info) = 0;
  // After each whole iteration (every branch of it stepped), when the solver's state is at an
  // iteration boundary: what a checkpoint written now continues from.
  virtual CallbackReturnType OnIterationEnd(const MutualBoostedSolver& /*solver*/, Stage /*stage*/,
                                            int /*iteration*/) {
    return CallbackReturnType::kContinue;
  }
};

// Why Solve returned (Ceres' TerminationType).
enum class TerminationType {
  kNotRun,
  kFinished,     // every stage ran to its end (warm-ups by auto-stop or their cap)
  kInterrupted,  // RequestStop(): at an iteration boundary; Solve again to continue
  kUserSuccess,  // a callback ended the run early; it counts as finished
  kUserAbort,    // a callback aborted the run
  kFailure,      // invalid options or loss table, a non-finite loss or gradient
};
const char* TerminationTypeName(TerminationType type);

// Where one stage's time went in one Solve call, when Profiler::Enabled() (mgsr_solve --profile).
struct StageProfile {
  Stage stage = Stage::kWarmup;
  int iterations = 0;                 // run in this Solve call
  double seconds = 0;                 // their wall time, including what no scope names
  std::vector<ProfileEntry> entries;  // per branch ("2DGS", "3DGS", "" for the solver) and scope
};

struct SolveSummary {
  TerminationType termination_type = TerminationType::kNotRun;
  std::string message;  // why it ended, one line
  // Per branch, indexed by BranchIndex (the 2DGS branch 0, the 3DGS branch 1).
  std::array<BranchSummary, 2> branches;
  const BranchSummary& branch(Branch b) const { return branches[BranchIndex(b)]; }
  int mutual_iterations = 0;
  double warmup_seconds = 0, mutual_seconds = 0;
  double exposure_fit_seconds = 0;  // the Ceres fits at the start of the mutual stage
  // With Profiler::Enabled(): one per stage this Solve call ran (not kept in checkpoints).
  std::vector<StageProfile> profile;
  std::string BriefReport() const;
  // Several lines: termination, iterations and time per stage, counts, final losses.
  std::string FullReport() const;
  // Finished, by the schedule or by a callback: the models are the run's result.
  bool IsFinished() const {
    return termination_type == TerminationType::kFinished ||
           termination_type == TerminationType::kUserSuccess;
  }
};

class MutualBoostedSolver {
 public:
  MutualBoostedSolver(const SolverOptions& options, const Scene& scene);

  void AddCallback(IterationCallback* callback) { callbacks_.push_back(callback); }
  // Runs (or continues, after LoadCheckpoint or an interruption) to the end. OK when it finished
  // or was interrupted (summary->termination_type says which; an interrupted state is at an
  // iteration boundary and can be saved and continued); an error, also in summary->message, on
  // failure or a callback's abort.
  Status Solve(SolveSummary* summary);
  // Asks Solve to return after the current iteration (safe from a signal handler or a callback).
  void RequestStop() { stop_requested_ = 1; }
  // The processes that share each batch of views (SolverOptions::batch_views); by default this
  // process alone. Every process of an MPI group runs the same solver on the same scene and
  // options and ends with the same models; the callbacks' requests (stop, abort) and
  // RequestStop() are agreed on at each iteration's end, so one process alone can end the run.
  // Set before Solve; the group must outlive the solver.
  void SetViewGroup(ViewGroup* group) { group_ = group; }

  // Everything needed to continue exactly: models, optimiser states, density statistics, the
  // random generator, the view order, the stage and iteration, the auto-stop windows.
  Status SaveCheckpoint(const std::string& path) const;
  Status LoadCheckpoint(const std::string& path);
  // What a checkpoint identifies a run by: every option (SolverOptions::Settings), and each view's
  // name, size, camera and split. Processes sharing batches compare them before training.
  std::string SettingsFingerprint() const;
  std::string SceneFingerprint() const;

  const GaussianModel& gaussians() const { return gaussians_->model(); }
  const SurfelModel& surfels() const { return surfels_->model(); }
  // For tools and tests that edit a model between runs (the optimiser state keeps its rows: change
  // values, not sizes).
  GaussianModel* mutable_gaussians() { return gaussians_->mutable_model(); }
  SurfelModel* mutable_surfels() { return surfels_->mutable_model(); }
  int active_sh_degree() const { return sh_degree_; }
  // A branch's learnt background (SolverOptions::environment), or null.
  const EnvironmentBackground* environment(Branch branch) const {
    return trainer(branch).environment();
  }
  // Per-view colour transforms (indexed like scene.views; identity for test views).
  const ExposureModel& exposure(Branch branch) const { return trainer(branch).exposure(); }

  // Renders of one view with the trained models (for outputs and evaluation). Without
  // `reflection` the 3DGS render skips its reflected chain: `tran`, depth and alpha are the same,
  // the composite is the transmitted colour (what a mesh's colour needs, at less cost).
  void RenderGaussians(const Camera& camera, GaussianRender* out, bool reflection = true) {
    GaussianRenderOptions o = gaussians_->RenderOptionsFor(camera);
    o.reflection = o.reflection && reflection;
    gaussians_->Render(o, out);
  }
  // With `distortion` off the 2DGS render leaves its depth distortion (a loss term's input, which
  // no output reads) empty: every other buffer is the same, at less cost.
  void RenderSurfels(const Camera& camera, SurfelRender* out, bool distortion = true) {
    SurfelRenderOptions o = surfels_->RenderOptionsFor(camera);
    o.distortion = distortion;
    surfels_->Render(o, out);
  }

 private:
  const BranchTrainer& trainer(Branch b) const { return *trainers_[BranchIndex(b)]; }
  BranchTrainer& trainer(Branch b) { return *trainers_[BranchIndex(b)]; }
  bool Trains(Branch b) const {
    return b == Branch::kSurfels2D ? options_.train_2d : options_.train_3d;
  }
  // What a branch's loss terms compare with on a view: the photo on the branch's background, the
  // mask, and `other`, the other branch's render in the mutual stage (the 3DGS transmitted image
  // for the 2DGS branch, the 2DGS depth for the 3DGS branch; null in the warm-up).
  // With multi-view rows also the view's photo in grey and its neighbours' cameras and photos.
  Targets LossTargets(Branch branch, int view, const Image* other) const;
  // Chooses every view's neighbours (once) and keeps the photos of `branch` in grey.
  void PrepareNeighbours(Branch branch);
  // One mutual step of `learner`, supervised by `teacher`'s render of the view (held constant; with
  // bidirectional supervision it then steps with the gradient of the learner's loss).
  Status MutualStep(BranchTrainer* learner, BranchTrainer* teacher, int iteration,
                    int schedule_iteration);
  // An error naming the branch, iteration and block when the last step's loss or gradient was not
  // finite (NaN or inf): the run stops before a bad state can reach a checkpoint.
  Status CheckFinite(const BranchTrainer& trainer, int iteration, double loss) const;
  void SetShDegree(int degree);
  int NextView();
  // The next batch of views (batch_views of them, from NextView) into batch_.
  void NextBatch();
  // Puts the batch's views back on the stack: the next NextBatch draws them again, in order.
  void ReturnBatch();
  // The loss table's rows, each added to its branch's trainer once, when Solve first runs.
  Status BuildProblems();
  // The fit of every training view's transform against the current renders
  // (solvers/exposure_fit.h).
  void FitExposures();
  // Pruning by contribution of every training branch over the training views (end of a stage).
  void PruneByContribution();
  // Calls the callbacks; what they ask is kept in callback_request_ for the iteration's end.
  void Notify(Stage stage, int iteration, const BranchTrainer& trainer, double loss);
  void NotifyIterationEnd(Stage stage, int iteration);
  // At the end of each iteration (the state at a boundary): the callbacks' OnIterationEnd, then
  // their requests and RequestStop(). True when Run must return (with *status); `last`: the run's
  // final iteration, where a stop request has nothing left to interrupt.
  bool EndIteration(Stage stage, int iteration, bool last, Status* status);
  // Solve's body; Solve fills the summary's termination from it.
  Status Run();
  // With profiling on: closes the current stage's profile (what the profiler recorded since the
  // last call) into the summary.
  void CloseStageProfile(Stage stage);
  int profile_iterations_ = 0;
  Timer profile_timer_;
  CallbackReturnType callback_request_ = CallbackReturnType::kContinue;

  SolverOptions options_;
  const Scene& scene_;
  std::vector<int> train_;
  // The views as the steps read them: [0] at the scene's size, [k] divided by
  // options_.CoarseLevelFactor(k) for each coarse level when options_.coarse_factor > 1; level_
  // is the one the current iteration trains on (SolverOptions::CoarseLevelAt). Multi-view terms
  // (PrepareNeighbours) add the photos in grey.
  std::vector<ViewLevel> levels_;
  int level_ = 0;
  const ViewLevel& views() const { return levels_[level_]; }
  // Trains the following steps on `level` (0: full size).
  void UseLevel(int level) { level_ = level < static_cast<int>(levels_.size()) ? level : 0; }
  // Multi-view terms: each view's neighbours (chosen once, on the scene's cameras).
  std::vector<std::vector<int>> neighbours_;
  Rng rng_;
  // Per-view colour transforms, indexed by BranchIndex; without exposure_per_branch the 2DGS
  // branch uses the 3DGS branch's.
  ExposureModel exposures_[2];
  std::unique_ptr<SurfelTrainer> surfels_;
  std::unique_ptr<GaussianTrainer> gaussians_;
  std::array<BranchTrainer*, 2> trainers_{};  // indexed by BranchIndex
  std::vector<int> view_stack_;
  std::vector<BatchView> batch_;  // the current iteration's views
  LocalViewGroup local_group_;
  ViewGroup* group_ = &local_group_;
  int sh_degree_ = 0;
  std::vector<IterationCallback*> callbacks_;
  IterationInfo iteration_info_[2];  // what Notify hands the callbacks, per branch
  Image mutual_target_;              // MutualStep's copy of the teacher's render of one view
  double start_time_ = 0;
  // Loop state (checkpointed).
  Stage stage_ = Stage::kWarmup;
  int next_iteration_ = 1;
  bool finished_ = false;
  SolveSummary summary_;
  bool problems_built_ = false;
  volatile std::sig_atomic_t stop_requested_ = 0;
};

}  // namespace mgsr
