#include "solvers/solver_options.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "solvers/density_strategy.h"

namespace mgsr {
namespace {

int Scaled(int value, double factor) {
  return std::max(1, static_cast<int>(std::lround(value * factor)));
}

}  // namespace

// fast: 20,000 -> 1,500 iterations per stage; every schedule keeps its place in the run.
constexpr double kFastScale = 0.075;
// fast's density control: the reference's intervals (they set how long opacities have to recover
// from a reset before the next prune), ending at two thirds of the warm-up cap, like the
// reference.
constexpr BranchSchedule kFastSchedule2D{100, 1000, 100, 500, 0.05f};
constexpr BranchSchedule kFastSchedule3D{50, 1000, 20, 500, 0.005f};

bool SolverOptions::FromPreset(const std::string& name, SolverOptions* o) {
  *o = SolverOptions();
  if (name != "paper" && name != "fast") return false;
  const double f = kFastScale;
  // Both presets shape the surface on fast's schedule: the 2DGS position rate decays over 2,250
  // iterations of each stage, and the normal and patch terms start after warm-up iteration 525
  // (the reference's 30,000 and 7,000, scaled). `paper`'s longer stages do not stretch them: in
  // the thousands of iterations at a high rate or without the normal terms, each step's one
  // view, lit its own way, bends the surfels to explain its light (docs/geometry.md, "Training
  // longer"). The 3DGS branch keeps the reference's decay in `paper`: its appearance gains from it.
  // (Where the views have masks, HoldGeometryAtFast gives both branches fast's schedules.)
  o->normal_from_iteration = Scaled(o->normal_from_iteration, f);
  o->multiview_from_iteration = Scaled(o->multiview_from_iteration, f);
  // Both presets warm up for fast's 1,125-1,500 iterations. The reference's 15,000-iteration
  // floor is what its auto-stop waits for; the paper's reason for the auto-stop is to keep a
  // branch from being over-optimised alone. By iteration 1,500 the 2DGS position rate is down to
  // a twentieth of its start; what a longer warm-up adds is each training view's own light fitted
  // into the surfels, and on the scenes without masks, backdrop-coloured surfaces off the object
  // (docs/geometry.md, "Training longer").
  o->warmup_min_iterations = Scaled(o->warmup_min_iterations, f);
  o->warmup_max_iterations = Scaled(o->warmup_max_iterations, f);
  if (name == "paper") {
    o->position_lr_max_steps_2d = Scaled(o->position_lr_max_steps, f);
    return true;
  }
  o->mutual_iterations = Scaled(o->mutual_iterations, f);
  o->distortion_from_iteration = Scaled(o->distortion_from_iteration, f);
  o->position_lr_max_steps = Scaled(o->position_lr_max_steps, f);  // both branches
  o->sh_interval = Scaled(o->sh_interval, f);
  o->auto_stop_window = 50;
  o->schedule_2d = kFastSchedule2D;
  o->schedule_3d = kFastSchedule3D;
  // Fewer, larger steps need a little more room per step to move.
  o->max_init_points = 20000;
  return true;
}

bool SolverOptions::HoldGeometryAtFast(SolverOptions* o) {
  SolverOptions paper, fast;
  FromPreset("paper", &paper);
  FromPreset("fast", &fast);
  if (!o->train_2d || !o->train_3d || o->bidirectional ||
      o->mutual_iterations <= fast.mutual_iterations)
    return false;
  // A value the command line changed stays.
  const auto take = [](auto* field, const auto& paper_value, const auto& fast_value) {
    if (*field == paper_value) *field = fast_value;
  };
  take(&o->schedule_2d, paper.schedule_2d, fast.schedule_2d);
  take(&o->schedule_3d, paper.schedule_3d, fast.schedule_3d);
  take(&o->position_lr_max_steps, paper.position_lr_max_steps, fast.position_lr_max_steps);
  take(&o->sh_interval, paper.sh_interval, fast.sh_interval);
  take(&o->auto_stop_window, paper.auto_stop_window, fast.auto_stop_window);
  take(&o->max_init_points, paper.max_init_points, fast.max_init_points);
  take(&o->distortion_from_iteration, paper.distortion_from_iteration,
       fast.distortion_from_iteration);
  o->mutual_iterations_2d = fast.mutual_iterations;
  return true;
}

void SolverOptions::ScaleIterationsForBatch(int views) {
  if (views <= 1) return;
  const double f = 1.0 / views;
  // 0 stays 0 ("from the start"); anything else stays >= 1.
  const auto scale = [f](int* v) {
    if (*v != 0) *v = Scaled(*v, f);
  };
  for (int* v : {&warmup_min_iterations, &warmup_max_iterations, &mutual_iterations,
                 &normal_from_iteration, &distortion_from_iteration, &multiview_from_iteration,
                 &position_lr_max_steps, &sh_interval})
    scale(v);
  if (position_lr_max_steps_2d > 0) scale(&position_lr_max_steps_2d);
  if (mutual_iterations_2d > 0) scale(&mutual_iterations_2d);
  auto_stop_window = std::max(2, Scaled(auto_stop_window, f));
  for (BranchSchedule* b : {&schedule_2d, &schedule_3d}) {
    for (int* v :
         {&b->densify_from, &b->densify_until, &b->densify_interval, &b->opacity_reset_interval})
      scale(v);
  }
  for (LossSpec& row : losses) scale(&row.first_iteration);
}

bool SolverOptions::ApplyMethod(const std::string& method, SolverOptions* o) {
  if (method == "mgsr") return true;
  if (method == "2dgs") {
    o->train_3d = false;
  } else if (method == "3dgs") {
    o->train_2d = false;
    o->reflection = false;
  } else if (method == "3dgs-ref") {
    o->train_2d = false;
  } else {
    return false;
  }
  o->warmup_max_iterations += o->mutual_iterations;
  o->mutual_iterations = 0;
  return true;
}

int SolverOptions::CoarseWarmupIterations() const {
  if (coarse_factor <= 1) return 0;
  return static_cast<int>(std::floor(coarse_fraction * warmup_max_iterations));
}

int SolverOptions::CoarseMutualIterations() const {
  if (coarse_factor <= 1) return 0;
  const int n = static_cast<int>(std::floor(coarse_fraction * mutual_iterations));
  // An alternate round (a 2DGS step on an odd iteration, the 3DGS step after it) reuses renders
  // within the round: it starts and ends at one size.
  return mutual_mode == "joint" ? n : n - n % 2;
}

int SolverOptions::CoarseLevelEnd(Stage stage, int k) const {
  const int n = stage == Stage::kWarmup ? CoarseWarmupIterations() : CoarseMutualIterations();
  const int levels = std::max(1, coarse_levels);
  if (k >= levels) return n;
  const int end = static_cast<int>(static_cast<int64_t>(n) * k / levels);
  // Alternate rounds stay whole at every switch, as at the switch to full size.
  const bool rounds = stage == Stage::kMutual && mutual_mode != "joint";
  return rounds ? end - end % 2 : end;
}

std::vector<int> SolverOptions::CoarseLevelEnds(Stage stage) const {
  std::vector<int> ends;
  if (coarse_factor <= 1 || CoarseLevelEnd(stage, coarse_levels) <= 0) return ends;
  for (int k = 1; k <= std::max(1, coarse_levels); ++k) ends.push_back(CoarseLevelEnd(stage, k));
  return ends;
}

std::vector<int> SolverOptions::CoarseFactors() const {
  std::vector<int> factors;
  for (int k = coarse_factor > 1 ? coarse_levels : 0; k >= 1; --k)
    factors.push_back(CoarseLevelFactor(k));
  return factors;
}

int SolverOptions::CoarseLevelAt(Stage stage, int iteration) const {
  if (coarse_factor <= 1) return 0;
  // Once per iteration: the spans' ends one by one, without building CoarseLevelEnds.
  const int levels = std::max(1, coarse_levels);
  for (int k = 1; k <= levels; ++k) {
    if (iteration <= CoarseLevelEnd(stage, k)) return levels - k + 1;
  }
  return 0;
}

Status SolverOptions::Validate() const {
  if (!train_2d && !train_3d) return Status::Error("at least one branch must train");
  if (warmup_max_iterations < 1) return Status::Error("--warmup_max_iterations must be >= 1");
  if (warmup_min_iterations < 0 || warmup_min_iterations > warmup_max_iterations) {
    return Status::Error("--warmup_min_iterations must be in [0, --warmup_max_iterations]");
  }
  if (mutual_iterations < 0) return Status::Error("--mutual_iterations must be >= 0");
  if (mutual_iterations_2d < -1)
    return Status::Error("--mutual_iterations_2d must be >= 0 (or -1: the whole mutual stage)");
  if (mutual_iterations_2d >= 0 && bidirectional)
    return Status::Error(
        "--mutual_iterations_2d: a held 2DGS branch cannot take --bidirectional's "
        "gradient");
  if (mutual_mode != "alternate" && mutual_mode != "joint") {
    return Status::Error("--mutual_mode must be alternate or joint, not '" + mutual_mode + "'");
  }
  if (auto_stop_window < 2) return Status::Error("--auto_stop_window must be >= 2");
  if (!(lambda_l1 >= 0 && lambda_l1 <= 1)) return Status::Error("--lambda_l1 must be in [0, 1]");
  if (!(normal_agreement_floor >= 0 && normal_agreement_floor <= 1))
    return Status::Error("--normal_agreement_floor must be in [0, 1]");
  if (!(mutual_transmitted_weight >= 0 && mutual_transmitted_weight <= 1)) {
    return Status::Error("--mutual_transmitted_weight must be in [0, 1]");
  }
  if (!(auto_stop_range >= 0)) return Status::Error("--auto_stop_range must be >= 0");
  if (multiview_neighbours < 1 || multiview_neighbours > kMaxNeighbours)
    return Status::Error("--multiview_neighbours must be in [1, " + std::to_string(kMaxNeighbours) +
                         "]");
  if (sh_degree < 0 || sh_degree > 3) return Status::Error("--sh_degree must be in [0, 3]");
  if (sh_interval < 1) return Status::Error("--sh_interval must be >= 1");
  if (position_lr_max_steps < 1) return Status::Error("--position_lr_max_steps must be >= 1");
  if (position_lr_max_steps_2d < 1 && position_lr_max_steps_2d != -1)
    return Status::Error(
        "--position_lr_max_steps_2d must be >= 1 (or -1: --position_lr_max_steps)");
  if (!(surfel_filter_sigma >= 0.01f && surfel_filter_sigma <= 2.0f))
    return Status::Error("--surfel_filter_sigma must be in [0.01, 2] pixels");
  for (double w :
       {w_2d, w_3d, w_depth, lambda_normal, lambda_normal_tv, lambda_distortion, depth_tv_warmup_2d,
        depth_tv_mutual_2d, transmitted_tv_3d, depth_tv_3d, lambda_multiview_ncc,
        lambda_multiview_depth, lambda_mask, lambda_surfel_layer}) {
    if (!(w >= 0) || !std::isfinite(w))
      return Status::Error("loss weights must be finite and >= 0");
  }
  if (lambda_mask_warmup != -1 && !(lambda_mask_warmup >= 0 && std::isfinite(lambda_mask_warmup)))
    return Status::Error("--lambda_mask_warmup must be finite and >= 0 (or -1: --lambda_mask's)");
  MGSR_RETURN_IF_ERROR(CheckLossTable(LossTable()));
  if (!(exposure_lr >= 0) || !std::isfinite(exposure_lr))
    return Status::Error("--exposure_lr must be finite and >= 0");
  if (!(exposure_prior >= 0) || !std::isfinite(exposure_prior))
    return Status::Error("--exposure_prior must be finite and >= 0");
  if (!(exposure_mean_prior >= 0) || !std::isfinite(exposure_mean_prior))
    return Status::Error("--exposure_mean_prior must be finite and >= 0");
  if (!(exposure_offset_prior >= 0) || !std::isfinite(exposure_offset_prior))
    return Status::Error("--exposure_offset_prior must be finite and >= 0");
  if (max_init_points < 1) return Status::Error("--max_init_points must be >= 1");
  if (!(prune_contribution >= 0) || !std::isfinite(prune_contribution))
    return Status::Error("--prune_contribution must be finite and >= 0");
  for (const auto& [trains, budget] :
       {std::make_pair(train_2d, max_surfels), std::make_pair(train_3d, max_gaussians)}) {
    if (!trains) continue;
    DensityContext context;
    context.density.max_primitives = budget;
    Status s;
    if (DensityStrategyRegistry::Get().Create(density, context, density_config, &s) == nullptr)
      return s.WithContext("--density: ");
  }
  if (!(background_2d >= 0 && background_2d <= 1) || !(background_3d >= 0 && background_3d <= 1))
    return Status::Error("background levels must be in [0, 1]");
  if (batch_views < 1) return Status::Error("--batch_views must be >= 1");
  if (coarse_factor < 1) return Status::Error("the coarse level's factor must be >= 1");
  // Each level halves the next: beyond 8 a level is under 1/256 of the coarse fit's size.
  if (coarse_levels < 1 || coarse_levels > 8)
    return Status::Error("--coarse_levels must be in [1, 8]");
  if (!(coarse_fraction >= 0 && coarse_fraction <= 1))
    return Status::Error("--coarse_fraction must be in [0, 1]");
  if (batch_views > 1 && bidirectional)
    return Status::Error("--bidirectional steps one view at a time: use --batch_views 1 with it");
  return Status::Ok();
}

namespace {

std::string Text(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.17g", v);
  return buffer;
}
std::string Text(const BranchSchedule& b) {
  return std::to_string(b.densify_from) + " " + std::to_string(b.densify_until) + " " +
         std::to_string(b.densify_interval) + " " + std::to_string(b.opacity_reset_interval) + " " +
         Text(b.min_opacity);
}

}  // namespace

std::string SolverOptions::CoarseSetting() const {
  if (coarse_factor <= 1) return "none";
  const std::string s = Text(coarse_factor) + " " + Text(coarse_fraction);
  return coarse_levels == 1 ? s : s + " " + Text(coarse_levels) + " levels";
}

std::vector<std::pair<std::string, std::string>> SolverOptions::Settings() const {
  return {{"auto_stop", Text(auto_stop)},
          {"warmup_min_iterations", Text(warmup_min_iterations)},
          {"warmup_max_iterations", Text(warmup_max_iterations)},
          {"auto_stop_window", Text(auto_stop_window)},
          {"auto_stop_range", Text(auto_stop_range)},
          {"mutual_iterations", Text(mutual_iterations)},
          {"mutual_iterations_2d", Text(mutual_iterations_2d)},
          {"mutual_mode", mutual_mode},
          {"bidirectional", Text(bidirectional)},
          {"train_2d", Text(train_2d)},
          {"train_3d", Text(train_3d)},
          {"reflection", Text(reflection)},
          {"lambda_l1", Text(lambda_l1)},
          {"lambda_normal", Text(lambda_normal)},
          {"normal_from_iteration", Text(normal_from_iteration)},
          {"normal_depth_gradient", Text(normal_depth_gradient)},
          {"lambda_normal_mutual", Text(lambda_normal_mutual)},
          {"lambda_normal_tv", Text(lambda_normal_tv)},
          {"normal_edge_weight", Text(normal_edge_weight)},
          {"normal_robust_scale", Text(normal_robust_scale)},
          {"normal_one_sided", Text(normal_one_sided)},
          {"normal_agreement_floor", Text(normal_agreement_floor)},
          {"lambda_distortion", Text(lambda_distortion)},
          {"distortion_from_iteration", Text(distortion_from_iteration)},
          {"lambda_mask", Text(lambda_mask)},
          {"lambda_mask_warmup", Text(lambda_mask_warmup)},
          {"lambda_multiview_ncc", Text(lambda_multiview_ncc)},
          {"lambda_multiview_depth", Text(lambda_multiview_depth)},
          {"lambda_surfel_layer", Text(lambda_surfel_layer)},
          {"multiview_from_iteration", Text(multiview_from_iteration)},
          {"multiview_neighbours", Text(multiview_neighbours)},
          {"depth_tv_warmup_2d", Text(depth_tv_warmup_2d)},
          {"depth_tv_mutual_2d", Text(depth_tv_mutual_2d)},
          {"transmitted_tv_3d", Text(transmitted_tv_3d)},
          {"depth_tv_3d", Text(depth_tv_3d)},
          {"tv_on_geometry", Text(tv_on_geometry)},
          {"tv_disparity_scale", Text(tv_disparity_scale)},
          {"w_2d", Text(w_2d)},
          {"w_3d", Text(w_3d)},
          {"w_depth", Text(w_depth)},
          {"mutual_transmitted_weight", Text(mutual_transmitted_weight)},
          {"mutual_image_weight", Text(mutual_image_weight)},
          {"schedule_2d", Text(schedule_2d)},
          {"schedule_3d", Text(schedule_3d)},
          {"densify_grad_threshold", Text(densify_grad_threshold)},
          {"percent_dense", Text(percent_dense)},
          {"max_gaussians", Text(static_cast<double>(max_gaussians))},
          {"max_surfels", Text(static_cast<double>(max_surfels))},
          {"density", density},
          {"density_config", density_config.dump()},
          {"prune_contribution", Text(prune_contribution)},
          {"position_lr_init", Text(position_lr_init)},
          {"position_lr_final", Text(position_lr_final)},
          {"position_lr_max_steps", Text(position_lr_max_steps)},
          {"position_lr_max_steps_2d", Text(position_lr_max_steps_2d)},
          {"feature_lr", Text(feature_lr)},
          {"opacity_lr", Text(opacity_lr)},
          {"scaling_lr", Text(scaling_lr)},
          {"rotation_lr", Text(rotation_lr)},
          {"surfel_shape_decay", Text(surfel_shape_decay)},
          {"sh_degree", Text(sh_degree)},
          {"sh_interval", Text(sh_interval)},
          {"background_2d", Text(background_2d)},
          {"background_3d", Text(background_3d)},
          {"environment", Text(environment)},
          {"surfel_area_preserving_low_pass", Text(surfel_area_preserving_low_pass)},
          {"surfel_filter_sigma", Text(surfel_filter_sigma)},
          {"surfel_orientation_from_points", Text(surfel_orientation_from_points)},
          {"spread_initial_surfels", Text(spread_initial_surfels)},
          {"exposure", ExposureModeName(exposure)},
          {"exposure_lr", Text(exposure_lr)},
          {"exposure_prior", Text(exposure_prior)},
          {"exposure_offset_prior", Text(exposure_offset_prior)},
          {"exposure_mean_prior", Text(exposure_mean_prior)},
          {"exposure_per_branch", Text(exposure_per_branch)},
          {"exposure_fit_at_mutual", Text(exposure_fit_at_mutual)},
          {"max_init_points", Text(static_cast<double>(max_init_points))},
          {"losses", LossTableToJson(LossTable()).dump()},
          {"seed", std::to_string(seed)},
          {"batch_views", Text(batch_views)},
          {"batch_sqrt_lr", Text(batch_sqrt_lr)},
          {"coarse", CoarseSetting()}};
}

}  // namespace mgsr
