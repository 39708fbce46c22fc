#include "solvers/mutual_boosted_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "mgsr/core/timer.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/model/init_from_points.h"
#include "solvers/exposure_fit.h"

namespace mgsr {
namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// Log-linear decay from init to final over max_steps (reference 1.8).
double PositionLearningRate(const SolverOptions& o, int step, double extent) {
  const double t = std::clamp(static_cast<double>(step) / o.position_lr_max_steps, 0.0, 1.0);
  return extent *
         std::exp(std::log(o.position_lr_init) * (1 - t) + std::log(o.position_lr_final) * t);
}

Adam::LearningRates Rates(const SolverOptions& o, int step, double extent) {
  return [&o, step, extent](const std::string& name, int width, std::vector<float>* rates) {
    float r = 0;
    if (name == "means")
      r = static_cast<float>(PositionLearningRate(o, step, extent));
    else if (name == "log_scales")
      r = static_cast<float>(o.scaling_lr);
    else if (name == "quats")
      r = static_cast<float>(o.rotation_lr);
    else if (name == "opacity_logits" || name == "ref_opacity_logits" || name == "beta_logits")
      r = static_cast<float>(o.opacity_lr);
    if (!o.reflection &&
        (name == "ref_sh" || name == "ref_opacity_logits" || name == "beta_logits")) {
      std::fill(rates->begin(), rates->end(), 0.0f);
      return;
    }
    if (name == "sh" || name == "ref_sh") {
      // Band 0 (the first 3 columns) at the feature rate, higher bands at 1/20 of it.
      for (int k = 0; k < width; ++k)
        (*rates)[k] = static_cast<float>(k < 3 ? o.feature_lr : o.feature_lr / 20);
      return;
    }
    std::fill(rates->begin(), rates->end(), r);
  };
}

// A branch's render as the buffers its loss terms read.
RenderBuffers SurfelBuffers(const Camera& camera, const SurfelRender& r) {
  RenderBuffers in;
  in.camera = &camera;
  in.Set(Buffer::kColor, &r.color);
  in.Set(Buffer::kDepth, &r.depth);
  in.Set(Buffer::kAlpha, &r.alpha);
  in.Set(Buffer::kNormal, &r.normal_world);
  in.Set(Buffer::kMedianDepth, &r.median_depth);
  in.Set(Buffer::kDistortion, &r.distortion);
  return in;
}

RenderBuffers GaussianBuffers(const Camera& camera, const GaussianRender& r) {
  RenderBuffers in;
  in.camera = &camera;
  in.Set(Buffer::kColor, &r.color);
  in.Set(Buffer::kTransmitted, &r.tran);
  in.Set(Buffer::kReflected, &r.ref);
  in.Set(Buffer::kWeight, &r.weight);
  in.Set(Buffer::kDepth, &r.depth);
  in.Set(Buffer::kAlpha, &r.alpha);
  return in;
}

void MoveGradients(RenderGradients* g, GaussianRenderGrad* out) {
  out->color = std::move(g->images[static_cast<int>(Buffer::kColor)]);
  out->tran = std::move(g->images[static_cast<int>(Buffer::kTransmitted)]);
  out->ref = std::move(g->images[static_cast<int>(Buffer::kReflected)]);
  out->weight = std::move(g->images[static_cast<int>(Buffer::kWeight)]);
  out->depth = std::move(g->images[static_cast<int>(Buffer::kDepth)]);
  out->alpha = std::move(g->images[static_cast<int>(Buffer::kAlpha)]);
}

void MoveGradients(RenderGradients* g, SurfelRenderGrad* out) {
  out->color = std::move(g->images[static_cast<int>(Buffer::kColor)]);
  out->depth = std::move(g->images[static_cast<int>(Buffer::kDepth)]);
  out->alpha = std::move(g->images[static_cast<int>(Buffer::kAlpha)]);
  out->normal_world = std::move(g->images[static_cast<int>(Buffer::kNormal)]);
  out->median_depth = std::move(g->images[static_cast<int>(Buffer::kMedianDepth)]);
  out->distortion = std::move(g->images[static_cast<int>(Buffer::kDistortion)]);
}

// After a branch's backward: densification statistics, the Adam step, then density control and
// opacity resets on the branch's schedule (reference 1.10). The same for both branches. Returns the
// name of a parameter block whose gradient was not finite ("" when all were).
template <typename Model>
std::string OptimizeAndControlDensity(const SolverOptions& o, const BranchSchedule& s, size_t budget,
                               int it, const Camera& camera, const std::vector<float>& mean2d_grads,
                               const std::vector<float>& radii, double extent, Model& grads,
                               Model* model, Adam* adam, DensityStats* stats, Rng* rng) {
  if (it < s.densify_until) {
    std::vector<float> norms;
    ScreenGradientNorms(mean2d_grads, camera.width, camera.height, &norms);
    stats->Accumulate(norms, radii);
  }
  const std::string nonfinite = adam->Step(model->Blocks(), grads.Blocks(), Rates(o, it, extent));
  if (!nonfinite.empty()) return nonfinite;  // the run stops: no density decisions on bad data
  if (it > s.densify_from && it < s.densify_until && it % s.densify_interval == 0) {
    DensityOptions d;
    d.grad_threshold = o.densify_grad_threshold;
    d.percent_dense = o.percent_dense;
    d.min_opacity = s.min_opacity;
    d.max_primitives = budget;
    DensifyAndPrune(model, adam, stats, d, extent, it > s.opacity_reset_interval, rng);
  }
  if (it < s.densify_until && it % s.opacity_reset_interval == 0) ResetOpacity(model, adam);
  return "";
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
    << (message.empty() ? "" : " (" + message + ")") << "\n"
    << "  warm-up 2DGS   " << warmup_iterations_2d << " iterations"
    << (auto_stopped_2d ? ", auto-stopped" : "") << ", final loss " << final_loss_2d << "\n"
    << "  warm-up 3DGS   " << warmup_iterations_3d << " iterations"
    << (auto_stopped_3d ? ", auto-stopped" : "") << ", final loss " << final_loss_3d << "\n"
    << "  mutual         " << mutual_iterations << " iterations\n"
    << "  time           warm-up " << warmup_seconds << " s, mutual " << mutual_seconds
    << " s (exposure fit " << exposure_fit_seconds << " s)\n"
    << "  primitives     " << num_surfels << " surfels, " << num_gaussians << " Gaussians\n";
  return s.str();
}

std::string SolveSummary::BriefReport() const {
  std::ostringstream s;
  s << "warm-up: 2DGS " << warmup_iterations_2d << " it" << (auto_stopped_2d ? " (auto-stop)" : "")
    << ", 3DGS " << warmup_iterations_3d << " it" << (auto_stopped_3d ? " (auto-stop)" : "") << ", "
    << warmup_seconds << " s; mutual: " << mutual_iterations << " it, " << mutual_seconds << " s; "
    << num_surfels << " surfels, " << num_gaussians << " Gaussians";
  return s.str();
}

MutualBoostedSolver::MutualBoostedSolver(const SolverOptions& options, const Scene& scene)
    : options_(options),
      scene_(scene),
      rng_(options.seed),
      stop_2d_(options.warmup_min_iterations, options.auto_stop_window, options.auto_stop_range),
      stop_3d_(options.warmup_min_iterations, options.auto_stop_window, options.auto_stop_range) {
  train_ = scene.TrainIndices();
  for (const View& v : scene.views) {
    ViewTargets t;
    t.gt_2d = CompositeOnBackground(v, options.background_2d);
    t.gt_3d = CompositeOnBackground(v, options.background_3d);
    targets_.push_back(std::move(t));
  }
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
  InitGaussiansFromPoints(points, colors, options.sh_degree, &gaussians_);
  InitSurfelsFromPoints(points, colors, options.sh_degree, options.seed + 1, &surfels_,
                        options.surfel_orientation_from_points ? SurfelOrientation::kNeighbourhood
                                                               : SurfelOrientation::kRandom);
  if (!options.reflection) {
    // Plain 3DGS: no reflected layer (sigmoid(-30) ~ 1e-13), and its blocks never learn.
    std::fill(gaussians_.ref_opacity_logits.begin(), gaussians_.ref_opacity_logits.end(), -30.0f);
  }
  stats_3d_.Reset(gaussians_.size());
  stats_2d_.Reset(surfels_.size());
  exposure_3d_.Reset(static_cast<int>(scene.views.size()), options.exposure, train_);
  exposure_2d_.Reset(static_cast<int>(scene.views.size()), options.exposure, train_);
}

Status MutualBoostedSolver::BuildProblems() {
  if (problems_built_) return Status::Ok();
  for (const LossSpec& row : options_.LossTable()) {
    Status status;
    std::unique_ptr<LossTerm> term = LossRegistry::Get().Create(row.term, row.config, &status);
    if (term == nullptr) return status.WithContext("loss row " + LossSpecId(row) + ": ");
    StageProblem& sp = ProblemFor(row.branch, row.stage);
    if (row.exposure && options_.exposure != ExposureMode::kOff) {
      auto wrapped = std::make_unique<ExposureCompensatedLoss>(std::move(term));
      sp.exposure_terms.push_back(wrapped.get());
      term = std::move(wrapped);
    }
    sp.problem.AddTerm(std::move(term), row.weight, row.branch, row.name);
    sp.rows.push_back(row);
  }
  problems_built_ = true;
  return Status::Ok();
}

double MutualBoostedSolver::EvaluateLoss(Branch branch, Stage stage, int view, int it,
                                         const RenderBuffers& in, const Targets& t,
                                         RenderGradients* grad) {
  StageProblem& sp = ProblemFor(branch, stage);
  for (size_t i = 0; i < sp.rows.size(); ++i)
    sp.problem.SetWeight(i, it >= sp.rows[i].first_iteration ? sp.rows[i].weight : 0.0);
  for (ExposureCompensatedLoss* e : sp.exposure_terms)
    e->set_transform(ExposureFor(branch).transform(view));
  if (!sp.checked) {
    // Once per branch and stage: every row's inputs and targets exist (a custom row may ask for a
    // buffer this branch does not render, or a target this stage does not have).
    const Status s = sp.problem.Check(branch, in, t);
    if (!s.ok()) {
      step_error_ = s.WithContext(std::string(branch == Branch::kSurfels2D ? "2DGS" : "3DGS") +
                                  " " + StageName(stage) + " loss row ");
      return std::numeric_limits<double>::quiet_NaN();
    }
    sp.checked = true;
  }
  std::vector<Problem::TermValue>& terms = last_terms_[branch == Branch::kSurfels2D ? 0 : 1];
  const double loss = sp.problem.Evaluate(branch, in, t, grad, &terms);
  if (!sp.exposure_terms.empty()) {
    ColorTransform gradient{};
    for (const ExposureCompensatedLoss* e : sp.exposure_terms) {
      for (int k = 0; k < kColorTransformSize; ++k) gradient[k] += e->parameter_gradient()[k];
    }
    ExposureFor(branch).Step(view, gradient, options_.exposure_lr, options_.exposure_prior,
                             options_.exposure_offset_prior, options_.exposure_mean_prior);
  }
  return loss;
}

void MutualBoostedSolver::FitExposures() {
  ExposureFitOptions fo;
  fo.mode = options_.exposure;
  fo.offset_prior = options_.exposure_offset_prior;
  for (int view : train_) {
    const View& v = scene_.views[view];
    const Image* mask = v.mask.empty() ? nullptr : &v.mask;
    GaussianRender g;
    RenderGaussians(v.camera, &g);
    ColorTransform p;
    if (FitColorTransform(g.color, targets_[view].gt_3d, mask, fo, &p).ok())
      exposure_3d_.SetTransform(view, p);
    if (options_.exposure_per_branch) {
      SurfelRender s;
      RenderSurfels(v.camera, &s);
      if (FitColorTransform(s.color, targets_[view].gt_2d, mask, fo, &p).ok())
        exposure_2d_.SetTransform(view, p);
    }
  }
}

int MutualBoostedSolver::NextView() {
  // A shuffled stack of the training views, refilled when empty (reference 1.3).
  if (view_stack_.empty()) {
    view_stack_ = train_;
    for (size_t i = view_stack_.size(); i > 1; --i)
      std::swap(view_stack_[i - 1], view_stack_[rng_.UniformInt(i)]);
  }
  const int v = view_stack_.back();
  view_stack_.pop_back();
  return v;
}

void MutualBoostedSolver::Notify(Stage stage, int iteration, Branch branch, double loss) {
  IterationInfo info{stage,           iteration,          branch, loss, gaussians_.size(),
                     surfels_.size(), Now() - start_time_,
                     last_terms_[branch == Branch::kSurfels2D ? 0 : 1]};
  for (IterationCallback* c : callbacks_) Request((*c)(info), &callback_request_);
}

void MutualBoostedSolver::NotifyIterationEnd(Stage stage, int iteration) {
  for (IterationCallback* c : callbacks_)
    Request(c->OnIterationEnd(*this, stage, iteration), &callback_request_);
}

GaussianRenderOptions MutualBoostedSolver::GaussianOptions(const Camera& camera) const {
  GaussianRenderOptions o;
  o.camera = camera;
  o.sh_degree = sh_degree_;
  const float bg = options_.background_3d;
  o.background[0] = o.background[1] = o.background[2] = bg;
  return o;
}

SurfelRenderOptions MutualBoostedSolver::SurfelOptions(const Camera& camera) const {
  SurfelRenderOptions o;
  o.camera = camera;
  o.sh_degree = sh_degree_;
  const float bg = options_.background_2d;
  o.background[0] = o.background[1] = o.background[2] = bg;
  o.low_pass = options_.surfel_area_preserving_low_pass ? SurfelLowPass::kAreaPreserving
                                                        : SurfelLowPass::kReference;
  o.filter_sigma = options_.surfel_filter_sigma;
  return o;
}

void MutualBoostedSolver::RenderGaussians(const Camera& camera, GaussianRender* out) {
  gaussian_renderer_.Forward(gaussians_, GaussianOptions(camera), out);
}

void MutualBoostedSolver::RenderSurfels(const Camera& camera, SurfelRender* out) {
  surfel_renderer_.Forward(surfels_, SurfelOptions(camera), out);
}

Targets MutualBoostedSolver::LossTargets(Branch branch, int view, const Image* other) const {
  const View& v = scene_.views[view];
  Targets t;
  t.mask = v.mask.empty() ? nullptr : &v.mask;
  if (branch == Branch::kSurfels2D) {
    t.image = &targets_[view].gt_2d;
    t.transmitted = other;
  } else {
    t.image = &targets_[view].gt_3d;
    t.other_depth = other;
  }
  return t;
}

double MutualBoostedSolver::StepSurfels(int view, Stage stage, int it, const Image* transmitted) {
  const View& v = scene_.views[view];
  const SolverOptions& o = options_;
  const SurfelRenderOptions ro = SurfelOptions(v.camera);
  SurfelRender render;
  surfel_renderer_.Forward(surfels_, ro, &render);

  // The 2DGS loss of the stage (the loss table; the paper's: reference 1.3 warm-up, 1.5 mutual).
  const Targets t =
      LossTargets(Branch::kSurfels2D, view, stage == Stage::kMutual ? transmitted : nullptr);
  const RenderBuffers in = SurfelBuffers(v.camera, render);
  RenderGradients g;
  const double loss = EvaluateLoss(Branch::kSurfels2D, stage, view, it, in, t, &g);
  if (!step_error_.ok()) return loss;
  SurfelRenderGrad rg;
  MoveGradients(&g, &rg);
  SurfelGradients grads;
  surfel_renderer_.Backward(surfels_, ro, render, rg, &grads);

  nonfinite_block_ = OptimizeAndControlDensity(o, o.schedule_2d, o.max_surfels, it, v.camera, grads.mean2d,
                            surfel_renderer_.projected().radius, scene_.extent, grads.params,
                            &surfels_, &adam_2d_, &stats_2d_, &rng_);
  return loss;
}

double MutualBoostedSolver::StepGaussians(int view, Stage stage, int it,
                                          const Image* surfel_depth) {
  const View& v = scene_.views[view];
  const SolverOptions& o = options_;
  const GaussianRenderOptions ro = GaussianOptions(v.camera);
  GaussianRender render;
  gaussian_renderer_.Forward(gaussians_, ro, &render);

  // The 3DGS loss of the stage (the loss table; the paper's: reference 1.4 warm-up, 1.5 mutual).
  const Targets t =
      LossTargets(Branch::kGaussians3D, view, stage == Stage::kMutual ? surfel_depth : nullptr);
  const RenderBuffers in = GaussianBuffers(v.camera, render);
  RenderGradients g;
  const double loss = EvaluateLoss(Branch::kGaussians3D, stage, view, it, in, t, &g);
  if (!step_error_.ok()) return loss;
  GaussianRenderGrad rg;
  MoveGradients(&g, &rg);
  GaussianGradients grads;
  gaussian_renderer_.Backward(gaussians_, ro, render, rg, &grads);

  nonfinite_block_ = OptimizeAndControlDensity(o, o.schedule_3d, o.max_gaussians, it, v.camera, grads.mean2d,
                            gaussian_renderer_.projected().radius, scene_.extent, grads.params,
                            &gaussians_, &adam_3d_, &stats_3d_, &rng_);
  return loss;
}

void MutualBoostedSolver::BackpropIntoGaussians(int view, int it, GaussianRender* render,
                                                Image d_transmitted) {
  const View& v = scene_.views[view];
  const GaussianRenderOptions ro = GaussianOptions(v.camera);
  GaussianRenderGrad rg;
  rg.tran = std::move(d_transmitted);
  GaussianGradients grads;
  gaussian_renderer_.Backward(gaussians_, ro, *render, rg, &grads);
  adam_3d_.Step(gaussians_.Blocks(), grads.params.Blocks(), Rates(options_, it, scene_.extent));
}

void MutualBoostedSolver::BackpropIntoSurfels(int view, int it, SurfelRender* render,
                                              Image d_depth) {
  const View& v = scene_.views[view];
  const SurfelRenderOptions ro = SurfelOptions(v.camera);
  SurfelRenderGrad rg;
  rg.depth = std::move(d_depth);
  SurfelGradients grads;
  surfel_renderer_.Backward(surfels_, ro, *render, rg, &grads);
  adam_2d_.Step(surfels_.Blocks(), grads.params.Blocks(), Rates(options_, it, scene_.extent));
}

Status MutualBoostedSolver::CheckFinite(Branch branch, int iteration, double loss) const {
  if (!step_error_.ok()) return step_error_;
  if (std::isfinite(loss) && nonfinite_block_.empty()) return Status::Ok();
  const std::string where = std::string(branch == Branch::kSurfels2D ? "2DGS" : "3DGS") + " " +
                            (stage_ == Stage::kWarmup ? "warm-up" : "mutual") + " iteration " +
                            std::to_string(iteration);
  if (!nonfinite_block_.empty()) {
    return Status::Error("non-finite gradient of parameter block '" + nonfinite_block_ + "' at " +
                         where + " (loss " + std::to_string(loss) +
                         "); stopped, the last checkpoint is the last good state");
  }
  return Status::Error("non-finite loss (" + std::to_string(loss) + ") at " + where +
                       "; stopped, the last checkpoint is the last good state");
}

Status MutualBoostedSolver::Solve(SolveSummary* summary) {
  summary_.message.clear();
  const Status s = Run();
  if (!s.ok()) {
    if (summary_.termination_type != TerminationType::kUserAbort)
      summary_.termination_type = TerminationType::kFailure;
    summary_.message = s.message();
  }
  summary_.num_gaussians = gaussians_.size();
  summary_.num_surfels = surfels_.size();
  *summary = summary_;
  return s;
}

bool MutualBoostedSolver::EndIteration(Stage stage, int iteration, bool last, Status* status) {
  NotifyIterationEnd(stage, iteration);
  const std::string where =
      std::string(stage == Stage::kWarmup ? "warm-up" : "mutual") + " iteration " +
      std::to_string(iteration);
  const CallbackReturnType request = callback_request_;
  callback_request_ = CallbackReturnType::kContinue;
  if (request == CallbackReturnType::kAbort) {
    summary_.termination_type = TerminationType::kUserAbort;
    *status = Status::Error("aborted by an iteration callback after " + where);
    return true;
  }
  if (request == CallbackReturnType::kTerminateSuccessfully) {
    finished_ = true;
    summary_.termination_type = TerminationType::kUserSuccess;
    summary_.message = "after " + where;
    *status = Status::Ok();
    return true;
  }
  if (stop_requested_ && !last) {
    summary_.termination_type = TerminationType::kInterrupted;
    summary_.message = "after " + where;
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
    sh_degree_ = options_.sh_degree;
    return Status::Ok();
  }
  MGSR_RETURN_IF_ERROR(options_.Validate());
  MGSR_RETURN_IF_ERROR(BuildProblems());
  if (train_.empty()) return Status::Error("the scene has no training views");
  if (gaussians_.size() == 0) return Status::Error("the scene has no initial points");
  stop_requested_ = 0;
  start_time_ = Now() - summary_.warmup_seconds - summary_.mutual_seconds;
  const SolverOptions& o = options_;
  SolveSummary& sum = summary_;
  Status ended;

  // Warm-up: the branches step in turn; each stops on its own.
  Timer warmup;
  const double warmup_before = sum.warmup_seconds;
  while (stage_ == Stage::kWarmup) {
    const bool done_2d =
        !o.train_2d || sum.auto_stopped_2d || sum.warmup_iterations_2d >= o.warmup_max_iterations;
    const bool done_3d =
        !o.train_3d || sum.auto_stopped_3d || sum.warmup_iterations_3d >= o.warmup_max_iterations;
    if (done_2d && done_3d) {
      if (o.exposure != ExposureMode::kOff && o.exposure_fit_at_mutual && o.train_2d &&
          o.train_3d) {
        Timer fit;
        sh_degree_ = o.sh_degree;
        FitExposures();
        sum.exposure_fit_seconds = fit.ElapsedSeconds();
      }
      stage_ = Stage::kMutual;
      next_iteration_ = 1;
      break;
    }
    const int it = next_iteration_;
    sh_degree_ = std::min(o.sh_degree, it / o.sh_interval);
    const int view = NextView();
    if (!done_2d) {
      sum.final_loss_2d = StepSurfels(view, Stage::kWarmup, it, nullptr);
      MGSR_RETURN_IF_ERROR(CheckFinite(Branch::kSurfels2D, it, sum.final_loss_2d));
      sum.warmup_iterations_2d = it;
      Notify(Stage::kWarmup, it, Branch::kSurfels2D, sum.final_loss_2d);
      sum.auto_stopped_2d = o.auto_stop && stop_2d_.Update(it, sum.final_loss_2d);
    }
    if (!done_3d) {
      sum.final_loss_3d = StepGaussians(view, Stage::kWarmup, it, nullptr);
      MGSR_RETURN_IF_ERROR(CheckFinite(Branch::kGaussians3D, it, sum.final_loss_3d));
      sum.warmup_iterations_3d = it;
      Notify(Stage::kWarmup, it, Branch::kGaussians3D, sum.final_loss_3d);
      sum.auto_stopped_3d = o.auto_stop && stop_3d_.Update(it, sum.final_loss_3d);
    }
    ++next_iteration_;
    sum.warmup_seconds = warmup_before + warmup.ElapsedSeconds();
    if (EndIteration(Stage::kWarmup, it, false, &ended)) return ended;
  }
  sh_degree_ = o.sh_degree;

  // Mutual stage: the supervising branch's render is a constant target.
  Timer mutual;
  const double mutual_before = sum.mutual_seconds;
  const bool both = o.train_2d && o.train_3d;
  while (both && next_iteration_ <= o.mutual_iterations) {
    const int it = next_iteration_;
    const int view = NextView();
    const bool joint = o.mutual_mode == "joint";
    const bool step_2d = joint || it % 2 == 1, step_3d = joint || it % 2 == 0;
    // The count the branch schedules (density control, opacity reset, learning rates) see. In
    // alternate mode the 2DGS branch steps on odd counts only, so it takes the count of the round
    // it opens: events on even counts then reach both branches, in the same round.
    const int schedule_it = joint ? it : it + it % 2;
    if (step_2d) {
      GaussianRender g;
      RenderGaussians(scene_.views[view].camera, &g);
      // Transmitted target, the 2DGS background (white) where the mask is background (ref. 1.5).
      Image target = std::move(g.tran);
      const Image& mask = scene_.views[view].mask;
      if (!mask.empty()) {
        for (int c = 0; c < 3; ++c) {
          for (size_t i = 0; i < target.plane_size(); ++i) {
            if (mask.plane(0)[i] == 0.0f) target.plane(c)[i] = o.background_2d;
          }
        }
      }
      // Bidirectional: the 2DGS image the loss compares with C_tran, before the 2DGS step.
      SurfelRender s2;
      if (o.bidirectional) RenderSurfels(scene_.views[view].camera, &s2);
      sum.final_loss_2d = StepSurfels(view, Stage::kMutual, schedule_it, &target);
      MGSR_RETURN_IF_ERROR(CheckFinite(Branch::kSurfels2D, it, sum.final_loss_2d));
      if (o.bidirectional) {
        // d L_2D / d C_tran from the loss table's rows that differentiate the transmitted target,
        // at the 2DGS render the loss compared. Pixels forced to the background are constants.
        TargetGradients d;
        ProblemFor(Branch::kSurfels2D, Stage::kMutual)
            .problem.EvaluateTargetGradient(
                Branch::kSurfels2D, SurfelBuffers(scene_.views[view].camera, s2),
                LossTargets(Branch::kSurfels2D, view, &target), &d);
        Image dt = std::move(d.transmitted);
        if (!dt.empty()) {
          if (!mask.empty()) {
            for (int c = 0; c < 3; ++c) {
              for (size_t i = 0; i < dt.plane_size(); ++i) {
                if (mask.plane(0)[i] == 0.0f) dt.plane(c)[i] = 0.0f;
              }
            }
          }
          // The Gaussian renderer still holds g's forward state (the 2DGS step does not use it).
          BackpropIntoGaussians(view, it, &g, std::move(dt));
        }
      }
      Notify(Stage::kMutual, it, Branch::kSurfels2D, sum.final_loss_2d);
    }
    if (step_3d) {
      SurfelRender s;
      RenderSurfels(scene_.views[view].camera, &s);
      // Bidirectional: the 3DGS depth the loss used, before the 3DGS step.
      GaussianRender g3;
      if (o.bidirectional) RenderGaussians(scene_.views[view].camera, &g3);
      sum.final_loss_3d = StepGaussians(view, Stage::kMutual, schedule_it, &s.depth);
      MGSR_RETURN_IF_ERROR(CheckFinite(Branch::kGaussians3D, it, sum.final_loss_3d));
      if (o.bidirectional) {
        // d L_3D / d Z2D from the rows that differentiate the 2DGS depth (the mutual depth loss),
        // at the 3DGS render the loss compared. The surfel renderer still holds the forward state
        // of `s` (the 3DGS step does not use it).
        TargetGradients d;
        ProblemFor(Branch::kGaussians3D, Stage::kMutual)
            .problem.EvaluateTargetGradient(
                Branch::kGaussians3D, GaussianBuffers(scene_.views[view].camera, g3),
                LossTargets(Branch::kGaussians3D, view, &s.depth), &d);
        if (!d.other_depth.empty()) BackpropIntoSurfels(view, it, &s, std::move(d.other_depth));
      }
      Notify(Stage::kMutual, it, Branch::kGaussians3D, sum.final_loss_3d);
    }
    sum.mutual_iterations = it;
    ++next_iteration_;
    sum.mutual_seconds = mutual_before + mutual.ElapsedSeconds();
    if (EndIteration(Stage::kMutual, it, next_iteration_ > o.mutual_iterations, &ended))
      return ended;
  }
  finished_ = true;
  sum.termination_type = TerminationType::kFinished;
  return Status::Ok();
}

}  // namespace mgsr
