#include "solvers/reconstruction_pipeline.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>

#include "mgsr/core/progress.h"
#include "mgsr/core/sha256.h"
#include "mgsr/core/timer.h"
#include "mgsr/eval/depth_error.h"
#include "mgsr/eval/exposure_alignment.h"
#include "mgsr/eval/ground_truth.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/eval/metrics_json.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/mesh_glb.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/io/output_folder.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/splat_formats.h"
#include "mgsr/mesh/exact_depth_ceiling.h"
#include "mgsr/render/visualize.h"
#include "mgsr/synth/ray_caster.h"
#include "solvers/backdrop.h"
#include "solvers/checkpoint_callback.h"
#include "solvers/density_control.h"
#include "solvers/eta_estimator.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/profile_report.h"
#include "solvers/trained_views.h"
#include "solvers/view_group.h"
#include "solvers/view_levels.h"

namespace mgsr {
namespace {

// The SHA-256 of a file's bytes ("" when it cannot be read).
std::string FileSha256(const std::string& path) {
  std::string bytes;
  return ReadFileToString(path, &bytes).ok() ? Sha256Hex(bytes) : "";
}

// The signed depth-error render (renders/<view>_depth2d_error.png) saturates at this many pixel
// footprints: the surface biases it shows are fractions of a pixel to a few pixels.
constexpr double kErrorMapFootprints = 2.0;

// A test view's render and photo as they are scored: the photo composited on the branch's
// background by its alpha; for an RGB photo with a separate mask, both composited through the
// mask, so the score is the object's and not the photo's backdrop's (which the model was never
// asked to reproduce on that background).
struct ScoredPair {
  Image render, truth;
};
ScoredPair ScoredImages(const View& v, const Image& render, float background) {
  ScoredPair p{render, CompositeOnBackground(v, background)};
  if (!v.alpha.empty() || v.mask.empty()) return p;
  for (int c = 0; c < 3; ++c) {
    for (size_t i = 0; i < p.render.plane_size(); ++i) {
      const float m = v.mask.data()[i];
      p.render.plane(c)[i] = render.plane(c)[i] * m + background * (1 - m);
      p.truth.plane(c)[i] = v.image.plane(c)[i] * m + background * (1 - m);
    }
  }
  return p;
}

// Test-view PSNR of the 3DGS composite every N iterations (after a 3DGS step, when the renderer's
// state is free to reuse), against the photo on the 3DGS branch's background: the composite the
// final evaluation scores.
class TestEvaluation : public IterationCallback {
 public:
  TestEvaluation(MutualBoostedSolver* solver, const Scene& scene, float background, int every)
      : solver_(solver), scene_(scene), background_(background), every_(every) {}
  CallbackReturnType operator()(const IterationInfo& i) override {
    if (every_ <= 0 || i.branch != Branch::kGaussians3D || i.iteration % every_ != 0)
      return CallbackReturnType::kContinue;
    const auto test = scene_.TestIndices();
    if (test.empty()) return CallbackReturnType::kContinue;
    double psnr = 0;
    for (int v : test) {
      GaussianRender r;
      solver_->RenderGaussians(scene_.views[v].camera, &r);
      const ScoredPair scored = ScoredImages(scene_.views[v], r.color, background_);
      psnr += std::min(100.0, Psnr(scored.render, scored.truth));
    }
    std::printf("[%s %5d] test PSNR %.2f dB (%zu views)\n",
                i.stage == Stage::kWarmup ? "warmup" : "mutual", i.iteration, psnr / test.size(),
                test.size());
    std::fflush(stdout);
    return CallbackReturnType::kContinue;
  }

 private:
  MutualBoostedSolver* solver_;
  const Scene& scene_;
  float background_;
  int every_;
};

std::string DepthLine(const char* label, const DepthErrorStats& d) {
  char line[200];
  std::snprintf(line, sizeof(line),
                "%s median %+.4f (%+.2f px), mean %+.4f, %.1f%% of pixels beyond 1 px", label,
                d.median, d.median_footprints, d.mean, 100 * d.share_beyond_footprint);
  return line;
}

std::string NormalLine(const char* label, const NormalErrorStats& n) {
  char line[200];
  std::snprintf(line, sizeof(line), "%s mean %.2f deg, median %.2f deg, %.1f%% beyond 10 deg",
                label, n.mean_deg, n.median_deg, 100 * n.share_beyond_10deg);
  return line;
}

// Signed depth error of the 2DGS branch on the training views when the warm-up ends (at the first
// mutual 2DGS step), against the ground truth. Written beside the checkpoint so a resumed run still
// reports it.
class DepthAfterWarmup : public IterationCallback {
 public:
  DepthAfterWarmup(MutualBoostedSolver* solver, const SolverOptions& options, const Scene& scene,
                   ExactDepthViews* ground_truth, std::string path)
      : solver_(solver),
        options_(options),
        scene_(scene),
        gt_(ground_truth),
        path_(std::move(path)) {}
  CallbackReturnType operator()(const IterationInfo& i) override {
    if (gt_ == nullptr || done_ || i.stage != Stage::kMutual || i.branch != Branch::kSurfels2D ||
        i.iteration != 1)
      return CallbackReturnType::kContinue;
    done_ = true;
    const SurfaceDepthReport r = MeasureSurfaceDepth(solver_, options_, scene_, gt_);
    std::printf("%s\n%s\n%s\n",
                DepthLine("depth after warm-up (train views): expected", r.expected).c_str(),
                DepthLine("                                    median  ", r.median).c_str(),
                NormalLine("2DGS normals after warm-up:         angle", r.normal).c_str());
    const nlohmann::json j = {{"expected", DepthErrorToJson(r.expected)},
                              {"median", DepthErrorToJson(r.median)},
                              {"normal", NormalErrorToJson(r.normal)}};
    const Status s = WriteStringToFileAtomic(path_, j.dump(2) + "\n");
    if (!s.ok()) std::fprintf(stderr, "warning: %s\n", s.message().c_str());
    return CallbackReturnType::kContinue;
  }
  const std::string& path() const { return path_; }

 private:
  MutualBoostedSolver* solver_;
  const SolverOptions& options_;
  const Scene& scene_;
  ExactDepthViews* gt_;
  std::string path_;
  bool done_ = false;
};

// Everything the ground truth lets us say about the geometry: the mesh's exact metrics beside the
// exact-depth ceiling of the same cameras and fusion (and of the training resolution when fusing
// finer), and the signed depth error after the warm-up and at the end.
Status ReportGeometry(MutualBoostedSolver* solver, const SolverOptions& options, const Scene& scene,
                      const GroundTruthGeometry& gt, ExactDepthViews* gt_depth,
                      const SurfaceOptions& surface, const TriangleMesh* mesh,
                      const std::string& warmup_depth_path, nlohmann::json* metrics) {
  const double footprint = TrainingFootprint(scene);
  MeshMetricsOptions mo;
  mo.pixel_footprint = footprint;
  if (!gt.visible_path.empty()) mo.completeness_points = &gt.visible_points;
  nlohmann::json& out = (*metrics)["mesh"];
  out["ground_truth"] = gt.mesh_path;
  if (!gt.visible_path.empty()) out["completeness_points"] = gt.visible_path;
  auto line = [&](const char* label, const MeshMetrics& m) {
    std::printf(
        "%s NC x100 %.2f, CD x1000 %.3f, signed offset %+.4f (%+.2f px, %.0f%% inside), "
        "F-score at 1 px %.3f\n",
        label, 100 * m.normal_consistency, 1000 * m.chamfer, m.signed_offset_median,
        m.signed_offset_median / footprint, 100 * m.fraction_inside, m.FScoreAtFootprints(1.0));
  };
  if (mesh != nullptr) {
    const MeshMetrics m = EvaluateMesh(*mesh, gt.mesh, mo);
    out.update(MeshMetricsToJson(m));
    line("mesh vs ground truth:   ", m);
  }
  TriangleMesh ceiling;
  MGSR_RETURN_IF_ERROR(ExactDepthCeiling(gt_depth, scene, surface, &ceiling));
  const MeshMetrics c = EvaluateMesh(ceiling, gt.mesh, mo);
  out["ceiling"] = MeshMetricsToJson(c);
  line("exact-depth ceiling:    ", c);
  if (surface.resolution_scale != 1) {
    SurfaceOptions one = surface;
    one.resolution_scale = 1;
    MGSR_RETURN_IF_ERROR(ExactDepthCeiling(gt_depth, scene, one, &ceiling));
    const MeshMetrics c1 = EvaluateMesh(ceiling, gt.mesh, mo);
    out["ceiling_1x"] = MeshMetricsToJson(c1);
    line("ceiling at 1x:          ", c1);
  }
  const SurfaceDepthReport d = MeasureSurfaceDepth(solver, options, scene, gt_depth);
  (*metrics)["depth"]["end"] = {{"expected", DepthErrorToJson(d.expected)},
                                {"median", DepthErrorToJson(d.median)},
                                {"normal", NormalErrorToJson(d.normal)}};
  std::printf("%s\n%s\n%s\n",
              DepthLine("depth at the end (train views): expected", d.expected).c_str(),
              DepthLine("                                median  ", d.median).c_str(),
              NormalLine("2DGS normals at the end:         angle", d.normal).c_str());
  std::string text;
  if (ReadFileToString(warmup_depth_path, &text).ok()) {
    try {
      (*metrics)["depth"]["after_warmup"] = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception&) {
      // A damaged side file only loses this figure.
    }
  }
  return Status::Ok();
}

// Progress lines and log.csv rows.
class ProgressLog : public IterationCallback {
 public:
  // A progress line follows each step of the last branch of a round (the 3DGS branch, or the 2DGS
  // branch when it trains alone); an untrained branch shows as "-".
  // For the time left: a density strategy that fills its budgets (MCMC) prices the rest of the
  // run at the budgets (0: none); one they only bound, at the model's present size.
  // With a coarse start (SolverOptions::coarse_factor) the steps at each size are priced from
  // the windows at that size; a size without windows yet is priced from the nearest size that has
  // them, by the ratio of pixels to the power 0.7 (kPixelCostExponent).
  ProgressLog(const std::string& csv_path, int every, const SolverOptions& options, bool append)
      : path_(csv_path),
        every_(every),
        options_(options),
        train_2d_(options.train_2d),
        train_3d_(options.train_3d),
        max_surfels_(options.max_surfels),
        max_gaussians_(options.max_gaussians),
        fills_budget_(options.density == "mcmc"),
        eta_(options.coarse_factor > 1 ? 1 + options.coarse_levels : 1) {
    const int trained_branches = (train_2d_ ? 1 : 0) + (train_3d_ ? 1 : 0);
    branches_ = trained_branches;
    mutual_steps_ = options.mutual_mode == "joint" ? 2 : 1;
    expected_ = trained_branches * options.warmup_max_iterations +
                mutual_steps_ * (trained_branches == 2 ? options.mutual_iterations : 0);
    // A resumed run continues the log; a missing or empty one (peek fails alike) starts with its
    // header.
    const bool header =
        !append || std::ifstream(csv_path).peek() == std::ifstream::traits_type::eof();
    csv_.open(csv_path, append ? std::ios::app : std::ios::trunc);
    if (header) csv_ << "stage,iteration,branch,loss,gaussians,surfels,seconds,terms\n";
  }
  // The rows so far reach the disk (at every checkpoint, so a killed run loses none it resumes
  // from); an error names the file.
  Status Flush() {
    csv_.flush();
    if (!csv_) return Status::Error(path_ + ": cannot write the training log");
    return Status::Ok();
  }
  CallbackReturnType operator()(const IterationInfo& i) override {
    const bool is2d = i.branch == Branch::kSurfels2D;
    const char* stage = i.stage == Stage::kWarmup ? "warmup" : "mutual";
    csv_ << stage << "," << i.iteration << "," << (is2d ? "2dgs" : "3dgs") << "," << i.loss << ","
         << i.num_gaussians << "," << i.num_surfels << "," << i.seconds << ",";
    // The loss table's active rows: name=weight x value, separated by ';'.
    for (size_t k = 0; k < i.terms.size(); ++k) {
      csv_ << (k ? ";" : "") << i.terms[k].name << "=" << i.terms[k].weight * i.terms[k].value;
    }
    csv_ << "\n";
    (is2d ? loss_2d_ : loss_3d_) = i.loss;
    ++steps_;
    // The trained branches' primitives, and where they are heading: the budgets while the model
    // still grows (a branch without one stays where it is).
    const double surfels = train_2d_ ? i.num_surfels : 0,
                 gaussians = train_3d_ ? i.num_gaussians : 0;
    const double primitives = surfels + gaussians;
    const int level = LevelAt(i.stage, i.iteration);
    if (steps_ == 1) window_ = {steps_, i.seconds, primitives, level};
    if (i.iteration % every_ == 0 && is2d != train_3d_) {
      // A window that spans a switch of size prices neither size.
      if (window_.level == level)
        eta_[level].AddWindow(steps_ - window_.steps, i.seconds - window_.seconds,
                              0.5 * (primitives + window_.primitives));
      const auto heading_for = [&](bool trained, double count, size_t budget) {
        if (!trained) return 0.0;
        return fills_budget_ && budget > 0 ? std::max<double>(count, budget) : count;
      };
      const double heading = heading_for(train_2d_, surfels, max_surfels_) +
                             heading_for(train_3d_, gaussians, max_gaussians_);
      window_ = {steps_, i.seconds, primitives, level};
      const double eta = SecondsLeft(i.stage, i.iteration, heading);
      const std::string loss_2d = train_2d_ ? Format("%.4f", loss_2d_) : "-";
      const std::string loss_3d = train_3d_ ? Format("%.4f", loss_3d_) : "-";
      const std::string surfels = train_2d_ ? std::to_string(i.num_surfels) : "-";
      const std::string gaussians = train_3d_ ? std::to_string(i.num_gaussians) : "-";
      std::printf(
          "[%s %5d] loss 2DGS %s 3DGS %s | surfels %s Gaussians %s | %.0f s, ~%.0f s left\n", stage,
          i.iteration, loss_2d.c_str(), loss_3d.c_str(), surfels.c_str(), gaussians.c_str(),
          i.seconds, eta);
      std::fflush(stdout);
    }
    return CallbackReturnType::kContinue;
  }

 private:
  std::string path_;
  std::ofstream csv_;
  static std::string Format(const char* format, double v) {
    char buffer[32];
    std::snprintf(buffer, sizeof(buffer), format, v);
    return buffer;
  }

  // The level (SolverOptions::CoarseLevelAt) of a step, within the estimators kept.
  int LevelAt(Stage stage, int iteration) const {
    return std::min(options_.CoarseLevelAt(stage, iteration), static_cast<int>(eta_.size()) - 1);
  }
  // The steps left after `iteration` of `stage` at each level (index 0: full size).
  std::vector<int> StepsLeft(Stage stage, int iteration) const {
    std::vector<int> left(eta_.size(), 0);
    // Adds the steps of `stage` after `from` at each level, `steps` per iteration.
    const auto add = [&](Stage s, int from, int last, int steps) {
      int start = 0;  // the end of the previous (coarser) level
      const std::vector<int> ends = options_.CoarseLevelEnds(s);
      for (size_t k = 0; k < ends.size(); ++k) {
        const int level =
            std::min(static_cast<int>(ends.size() - k), static_cast<int>(left.size()) - 1);
        left[level] += steps * std::max(0, ends[k] - std::max(from, start));
        start = ends[k];
      }
      left[0] += steps * std::max(0, last - std::max(from, start));
    };
    const int mutual = branches_ == 2 ? options_.mutual_iterations : 0;
    if (stage == Stage::kWarmup) {
      add(Stage::kWarmup, iteration, options_.warmup_max_iterations, branches_);
      add(Stage::kMutual, 0, mutual, mutual_steps_);
    } else {
      add(Stage::kMutual, iteration, mutual, mutual_steps_);
    }
    // Never more than the run's own count of steps left (a safety: the stages' spans above
    // already follow the iteration counter; what is cut is full-size steps first).
    int over = -std::max(0, expected_ - steps_);
    for (int n : left) over += n;
    for (size_t k = 0; over > 0 && k < left.size(); ++k) {
      const int cut = std::min(over, left[k]);
      left[k] -= cut;
      over -= cut;
    }
    return left;
  }

  // The time left after `iteration` of `stage`: the remaining steps at each size, each priced by
  // the windows of their size.
  double SecondsLeft(Stage stage, int iteration, double heading) const {
    // A full-size step costs less than the ratio of pixels times a coarse one: the per-primitive
    // passes do not shrink with the views and the raster passes shrink to about a third at half
    // size (docs/performance.md, "Coarse start"). A full-size step took 2.5 (512 px synthetic
    // object) and 2.75 (1600 px capture) coarse steps at factor 2: 4^0.66 and 4^0.73.
    constexpr double kPixelCostExponent = 0.7;
    const std::vector<int> left = StepsLeft(stage, iteration);
    double seconds = 0;
    for (size_t k = 0; k < left.size(); ++k) {
      if (left[k] == 0) continue;
      // The nearest size with windows (the full size when none has any yet).
      size_t from = 0;
      for (size_t d = 0; d < eta_.size(); ++d) {
        if (k >= d && eta_[k - d].has_windows()) {
          from = k - d;
          break;
        }
        if (k + d < eta_.size() && eta_[k + d].has_windows()) {
          from = k + d;
          break;
        }
      }
      const double pixels =
          static_cast<double>(options_.CoarseLevelFactor(static_cast<int>(from))) /
          options_.CoarseLevelFactor(static_cast<int>(k));
      seconds += left[k] * eta_[from].SecondsPerStep(heading) *
                 std::pow(pixels * pixels, kPixelCostExponent);
    }
    return seconds;
  }

  int every_;
  SolverOptions options_;
  int expected_ = 0, steps_ = 0, branches_ = 0, mutual_steps_ = 1;
  bool train_2d_, train_3d_;
  size_t max_surfels_, max_gaussians_;
  bool fills_budget_;
  // Where the latest progress window started: steps, seconds, primitives, level.
  struct {
    int steps;
    double seconds, primitives;
    int level;
  } window_ = {0, 0, 0, 0};
  std::vector<EtaEstimator> eta_;  // per level (SolverOptions::CoarseLevelAt), 0 the full size
  double loss_2d_ = 0, loss_3d_ = 0;
};

// Every training view has a mask or an alpha channel: the object's pixels are known.
bool ForegroundKnown(const Scene& scene) {
  const std::vector<int> train = scene.TrainIndices();
  for (int i : train) {
    if (scene.views[i].mask.empty() && scene.views[i].alpha.empty()) return false;
  }
  return !train.empty();
}

// Sets both branches' backgrounds from a parsed --background; returns what was chosen and why.
std::string ChooseBackground(const std::string& flag, double level, const Scene& scene,
                             SolverOptions* o) {
  if (level >= 0) {
    o->background_2d = o->background_3d = static_cast<float>(level);
    return "grey " + flag + " (both branches, --background)";
  }
  const std::string environment =
      "learnt per viewing direction (a 64x32 environment map per branch)";
  if (flag == "env") {
    o->environment = true;
    return environment + ", --background env";
  }
  if (flag == "auto") {
    const Backdrop b = EstimateBackdrop(scene);
    if (b.uniform) {
      o->background_2d = o->background_3d = b.level;
      return "the photos' uniform backdrop, grey " + std::to_string(b.level) + " (both branches)";
    }
    if (!ForegroundKnown(scene)) {
      // No masks and a backdrop that varies: a scene in the world (sky, ground, walls).
      o->environment = true;
      return environment + ": no masks and " + b.reason;
    }
    return "reference (2DGS white, 3DGS black): " + b.reason;
  }
  return "reference (2DGS white, 3DGS black)";
}

// The test views' scores, summed over the views and then averaged.
struct TestScores {
  std::vector<int> views;
  double psnr = 0, ssim = 0, psnr_aligned = 0, ssim_aligned = 0;
  double psnr_foreground = 0;  // over the views with a mask (foreground_views)
  int foreground_views = 0;
  double depth_error = 0;  // mean |depth - truth| per view, summed over depth_views
  int depth_views = 0;
  nlohmann::json per_view = nlohmann::json::array();
};

}  // namespace

Status ParseBackground(const std::string& background, double* level) {
  *level = -1;
  if (background == "auto" || background == "reference" || background == "env") return Status::Ok();
  char* end = nullptr;
  const double v = std::strtod(background.c_str(), &end);
  if (end == background.c_str() || *end != '\0' || !(v >= 0 && v <= 1)) {
    return Status::Error(
        "--background must be auto, reference, env or a grey level in [0, 1], not '" + background +
        "'");
  }
  *level = v;
  return Status::Ok();
}

Status ReconstructionOptions::CheckInputsAndOutput() const {
  if (workspace.empty() == images.empty())
    return Status::Error("give either --workspace or --images");
  if (!masks.empty() && images.empty())
    return Status::Error("--masks goes with --images (a workspace has its own masks/)");
  if (output.empty() && !(check_only && !resume)) return Status::Error("--output is required");
  if (check_only && !images.empty())
    return Status::Error("--check goes with --workspace (--images would run colmap)");
  if (resume && overwrite) return Status::Error("--resume and --overwrite exclude each other");
  return Status::Ok();
}

Status ReconstructionOptions::Validate() const {
  MGSR_RETURN_IF_ERROR(CheckInputsAndOutput());
  if (log_every < 1) return Status::Error("--log_every must be >= 1");
  if (!(surface.voxel_size >= 0)) return Status::Error("--voxel_size must be >= 0");
  if (surface.resolution_scale < 1 || surface.resolution_scale > 8)
    return Status::Error("--mesh_resolution_scale must be between 1 and 8");
  if (!(surface.truncation_voxels > 0)) return Status::Error("--tsdf_truncation must be > 0");
  if (checkpoint_every < 0) return Status::Error("--checkpoint_every must be >= 0");
  {
    std::string joined;
    for (const std::string& f : export_formats) joined += f + ",";
    std::vector<std::string> parsed;
    MGSR_RETURN_IF_ERROR(ParseExportFormats(joined, &parsed));
    if (parsed.size() != export_formats.size())
      return Status::Error("--export: a format is named twice");
  }
  if (eval_every < 0) return Status::Error("--eval_every must be >= 0");
  if (max_gaussians < -1 || max_surfels < -1)
    return Status::Error(
        "--max_gaussians and --max_surfels must be -1 (from --budget), 0 (none) or a count");
  if (!budget.empty() && budget != "auto" && budget != "scene" && budget != "none" &&
      (budget.find_first_not_of("0123456789") != std::string::npos || budget.size() > 12))
    return Status::Error("--budget must be auto, scene, none or a count, not '" + budget + "'");
  double level = 0;
  MGSR_RETURN_IF_ERROR(ParseBackground(background, &level));
  // The budgets are set once the scene is read; until then a placeholder stands for each one that
  // will come from --budget (none stays none, so "mcmc needs a budget" shows before any work).
  SolverOptions check = solver;
  const size_t placeholder = budget == "none" ? 0 : 1;
  check.max_gaussians = max_gaussians >= 0 ? max_gaussians : placeholder;
  check.max_surfels = max_surfels >= 0 ? max_surfels : placeholder;
  return check.Validate();
}

void ReconstructionPipeline::RequestStop() {
  stop_requested_ = 1;
  MutualBoostedSolver* solver = solver_;
  if (solver != nullptr) solver->RequestStop();
}

Status ReconstructionPipeline::Train(MutualBoostedSolver* solver, SolveSummary* summary) {
  solver_ = solver;
  // The pointer RequestStop uses goes with the training, however it ends.
  struct Forget {
    MutualBoostedSolver* volatile* solver;
    ~Forget() { *solver = nullptr; }
  } forget{&solver_};
  Profiler::SetEnabled(options_.profile);
  const Status s = solver->Solve(summary);
  Profiler::SetEnabled(false);
  return s;
}

Status ReconstructionPipeline::TrainAlongside(MutualBoostedSolver* solver,
                                              const SolverOptions& options, const Scene& scene,
                                              const SurfaceOptions& surface,
                                              ReconstructionEnd* end) {
  if (options_.check_only) {
    *end = ReconstructionEnd::kChecked;
    return Status::Ok();
  }
  SolveSummary summary;
  const Status s = Train(solver, &summary);
  if (!s.ok()) return s;
  if (summary.termination_type == TerminationType::kInterrupted) {
    *end = ReconstructionEnd::kInterrupted;
    return Status::Ok();
  }
  // Process 0 writes the models and test views, then fuses the mesh with these frames.
  TriangleMesh none;
  return ExtractSurface(solver, options, scene, surface, &none, {}, options_.group);
}

// Everything one run carries from stage to stage. The solver keeps references to `scene` and its
// callbacks to `options`, so the state stays where Run put it.
struct ReconstructionPipeline::RunState {
  SolverOptions options;  // the solver's, with the scene's choices applied
  std::string workspace;  // the input workspace (colmap's dense folder when given photos)
  double background_level = -1;
  std::string ckpt_dir, ckpt;
  bool writer = true;  // process 0 of a group (or no group): writes every output
  OutputFolder out;
  Timer total;
  nlohmann::json colmap_metrics;
  Scene scene;
  double load_seconds = 0;
  std::string background_note, budget_mode, budget_why, region_note;
  SeenThroughStats free_space;  // what the mesh's free-space test removed
  SurfaceOptions surface;
  std::unique_ptr<MutualBoostedSolver> solver;
  std::unique_ptr<ProgressLog> log;
  std::unique_ptr<TestEvaluation> evaluation;
  std::unique_ptr<CheckpointCallback> checkpointer;
  GroundTruthGeometry ground_truth;
  std::unique_ptr<RayCaster> gt_caster;
  // The training views' exact depth, cast once for the three readers (warm-up check, ceiling, end).
  std::unique_ptr<ExactDepthViews> gt_depth;
  std::unique_ptr<DepthAfterWarmup> depth_after_warmup;
  SolveSummary summary;
  TestScores test;
  TriangleMesh mesh;
  std::string mesh_path;
  double mesh_seconds = 0;
  ReconstructionEnd end = ReconstructionEnd::kFinished;
  bool stopped = false;  // a stage ended the run early without an error (check, Ctrl-C, follower)
};

Status ReconstructionPipeline::Run(ReconstructionEnd* end) {
  RunState st;
  const Status s = RunStages(&st);
  // A failure takes back the results this run wrote: no folder looks finished unless it is.
  if (!s.ok()) st.out.Discard();
  *end = st.end;
  return s;
}

Status ReconstructionPipeline::RunStages(RunState* st) {
  using Stage = Status (ReconstructionPipeline::*)(RunState*);
  for (const Stage stage : {
           &ReconstructionPipeline::OpenOutput,           // options checked, output locked
           &ReconstructionPipeline::RunColmap,            // photos -> workspace
           &ReconstructionPipeline::LoadInput,            // the scene
           &ReconstructionPipeline::ChooseSceneSettings,  // backgrounds and weights
           &ReconstructionPipeline::ChooseBudget,         // primitives per branch
           &ReconstructionPipeline::ChooseCoarseLevel,    // the coarse start's size
           &ReconstructionPipeline::ChooseMeshRegion,     // where the mesh may be
           &ReconstructionPipeline::ChooseBatches,        // views per step; options final
           &ReconstructionPipeline::CreateSolver,         // models, group, checkpoint
           &ReconstructionPipeline::FollowOrCheck,        // other processes, --check
           &ReconstructionPipeline::PrepareOutputs,       // folders, log, callbacks
           &ReconstructionPipeline::TrainModels,          // warm-up and mutual rounds
           &ReconstructionPipeline::WriteModels,          // point_cloud_*.ply, backgrounds
           &ReconstructionPipeline::ScoreTestViews,       // PSNR/SSIM and renders
           &ReconstructionPipeline::ExtractMesh,          // TSDF fusion -> mesh.ply
           &ReconstructionPipeline::WriteMetrics,         // metrics.json; the run is done
       }) {
    MGSR_RETURN_IF_ERROR((this->*stage)(st));
    if (st->stopped) break;
  }
  return Status::Ok();
}

Status ReconstructionPipeline::OpenOutput(RunState* st) {
  const ReconstructionOptions& o = options_;
  MGSR_RETURN_IF_ERROR(o.Validate());
  st->options = o.solver;
  st->workspace = o.workspace;
  MGSR_RETURN_IF_ERROR(ParseBackground(o.background, &st->background_level));
  st->ckpt_dir = JoinPath(o.output, "checkpoints");
  st->ckpt = JoinPath(st->ckpt_dir, "latest.ckpt");
  if (o.resume && !FileExists(st->ckpt))
    return Status::Error(st->ckpt + ": no checkpoint to resume from");
  // In a group of processes, process 0 writes; the others train alongside it (TrainAlongside).
  st->writer = o.group == nullptr || o.group->rank() == 0;
  if (o.group != nullptr && o.group->size() > 1) {
    if (!o.images.empty()) {
      return Status::Error(
          "--images with " + std::to_string(o.group->size()) +
          " MPI processes: run the photo pipeline in one process first (mgsr_solve --images ... "
          "--check, or mgsr_colmap), then mpirun on its workspace (OUTPUT/colmap/dense)");
    }
    MGSR_RETURN_IF_ERROR(CheckBatchSplit(st->options.batch_views, o.group->size()));
  }
  // Opening the output locks it, creating it when missing: first make sure the input is there
  // (an output inside a mistyped workspace path must not create that path).
  if (o.images.empty() && !DirectoryExists(st->workspace))
    return Status::Error(st->workspace + ": scene folder does not exist");
  if (!o.images.empty() && !DirectoryExists(o.images))
    return Status::Error(o.images + ": folder of photos does not exist");
  if (!o.check_only && st->writer) {
    MGSR_RETURN_IF_ERROR(OutputFolder::Open(o.output,
                                            o.resume      ? OutputMode::kResume
                                            : o.overwrite ? OutputMode::kOverwrite
                                                          : OutputMode::kFresh,
                                            &st->out));
  }
  st->total.Restart();
  return Status::Ok();
}

Status ReconstructionPipeline::RunColmap(RunState* st) {
  const ReconstructionOptions& o = options_;
  if (o.images.empty()) return Status::Ok();
  ColmapPipelineOptions co = o.colmap;
  co.images = o.images;
  co.masks = o.masks;
  co.workspace = JoinPath(o.output, "colmap");
  const std::string dense = JoinPath(co.workspace, "dense");
  st->workspace = dense;
  if (o.resume && DirectoryExists(JoinPath(dense, "sparse"))) {
    std::printf("colmap: reusing %s (--resume)\n", dense.c_str());
    return Status::Ok();
  }
  MGSR_RETURN_IF_ERROR(st->out.Prepare());  // colmap writes into the output folder
  ColmapPipelineSummary cs;
  MGSR_RETURN_IF_ERROR(RunColmapPipeline(co, &cs));
  if (o.on_colmap_summary) o.on_colmap_summary(cs);
  st->colmap_metrics = {{"images_given", cs.images_given},
                        {"images_registered", cs.images_registered},
                        {"unregistered", cs.unregistered},
                        {"points", cs.points},
                        {"mean_reprojection_error_px", cs.mean_reprojection_error}};
  for (const auto& step : cs.steps) st->colmap_metrics["seconds"][step.name] = step.seconds;
  return Status::Ok();
}

Status ReconstructionPipeline::LoadInput(RunState* st) {
  Timer load_timer;
  Scene& scene = st->scene;
  MGSR_RETURN_IF_ERROR(LoadScene(st->workspace, options_.scene, &scene));
  MGSR_RETURN_IF_ERROR(CheckTrainable(scene));
  for (const std::string& w : scene.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  for (const std::string& n : scene.notes) std::printf("photos: %s\n", n.c_str());
  st->load_seconds = load_timer.ElapsedSeconds();
  const Camera& cam0 = scene.views.front().camera;
  std::printf("scene: %s (%s), %zu train / %zu test views, %dx%d, %zu points, masks: %s\n",
              st->workspace.c_str(), scene.source.c_str(), scene.TrainIndices().size(),
              scene.TestIndices().size(), cam0.width, cam0.height, scene.points.size(),
              scene.has_masks() ? "yes" : "no (gamma = 1, mesh not masked)");
  return Status::Ok();
}

Status ReconstructionPipeline::ChooseSceneSettings(RunState* st) {
  const ReconstructionOptions& o = options_;
  SolverOptions& options = st->options;
  st->background_note = ChooseBackground(o.background, st->background_level, st->scene, &options);
  std::printf("background: %s\n", st->background_note.c_str());
  const bool foreground = ForegroundKnown(st->scene);
  if (o.normal_weight_from_scene) {
    options.lambda_normal = foreground ? kNormalWeightWithForeground : kReferenceNormalWeight;
    std::printf("normal weight: %g (%s)\n", options.lambda_normal,
                foreground ? "the views have masks or alpha"
                           : "the reference's: no masks or alpha to tell the object from its "
                             "backdrop");
  }
  if (o.distortion_from_scene) {
    options.lambda_distortion = foreground ? 0.0 : kDistortionWeightWithoutForeground;
    std::printf("depth distortion: %g (%s)\n", options.lambda_distortion,
                foreground ? "the reference's: the views have masks or alpha"
                           : "no masks or alpha: keeps the surfels in one layer");
  }
  if (foreground && o.geometry_hold_from_scene && SolverOptions::HoldGeometryAtFast(&options)) {
    std::printf(
        "geometry: the 2DGS branch trains for the first %d of %d mutual iterations, then is held "
        "while the 3DGS branch trains on, both on fast's schedules (the views have masks or "
        "alpha)\n",
        options.mutual_iterations_2d, options.mutual_iterations);
  }
  if (o.spread_from_scene) {
    options.spread_initial_surfels = foreground;
    if (foreground)
      std::printf(
          "initial disks: spread over the points' surfaces to the 2DGS budget (the views have "
          "masks or alpha)\n");
  }
  if (o.surfel_layer_from_spread) {
    options.lambda_surfel_layer =
        options.spread_initial_surfels ? SolverOptions::kSurfelLayerWeightWithSpread : 0.0;
    if (options.spread_initial_surfels)
      std::printf("surfel layer prior: %g (the initial disks are spread)\n",
                  options.lambda_surfel_layer);
  }
  if (foreground && (o.mask_from_scene || o.one_sided_from_scene)) {
    if (o.mask_from_scene) options.lambda_mask = kMaskWeightWithForeground;
    if (o.one_sided_from_scene) options.normal_one_sided = true;
    std::printf(
        "silhouette term: %g in the warm-up, %g in the mutual stage, normal consistency "
        "one-sided at depth steps: %s (the views have masks or alpha)\n",
        options.MaskWarmupWeight(), options.lambda_mask, options.normal_one_sided ? "yes" : "no");
  }
  if (o.depth_tv_from_scene && options.environment) {
    options.depth_tv_warmup_2d = options.depth_tv_mutual_2d = options.depth_tv_3d = 0;
    std::printf(
        "depth TVs: off (a scene in the world, learnt background: they would pull on its "
        "grounds and walls)\n");
  }
  if (o.depth_tv_disparity) {
    options.tv_disparity_scale = ObjectDistance(st->scene);
    std::printf("depth TV: on the disparity s^2 / D, s = %.4g (the cameras' distance)\n",
                options.tv_disparity_scale);
  }
  // A loss configuration edits the table these weights give, the scene's choices included.
  if (!o.loss_config.empty()) {
    options.losses = PaperLossTable(options);
    MGSR_RETURN_IF_ERROR(ApplyLossConfigFile(o.loss_config, &options.losses));
  }
  return Status::Ok();
}

Status ReconstructionPipeline::ChooseBudget(RunState* st) {
  const ReconstructionOptions& o = options_;
  SolverOptions& options = st->options;
  // The budget: --budget for both branches unless --max_gaussians / --max_surfels give one.
  st->budget_mode = !o.budget.empty() ? o.budget : (options.density == "mcmc" ? "auto" : "scene");
  size_t budget_3d = 0, budget_2d = 0;
  if (st->budget_mode == "auto") {
    const SceneBudget b = AutoPrimitiveBudget(st->scene);
    budget_3d = b.gaussians;
    budget_2d = b.surfels;
    st->budget_why = b.why;
  } else if (st->budget_mode == "scene") {
    budget_3d = budget_2d = DefaultPrimitiveBudget(st->scene);
    st->budget_why =
        "scene: 4 per pixel of a training view, at least 500,000 (a bound, not a target)";
  } else if (st->budget_mode == "none") {
    st->budget_why = "none";
  } else {
    budget_3d = budget_2d = std::stoull(st->budget_mode);
    st->budget_why = "given: --budget " + st->budget_mode;
  }
  options.max_gaussians = o.max_gaussians < 0 ? budget_3d : o.max_gaussians;
  options.max_surfels = o.max_surfels < 0 ? budget_2d : o.max_surfels;
  if (o.max_gaussians >= 0 || o.max_surfels >= 0) st->budget_why += "; per branch as given";
  const auto budget_text = [](size_t n) {
    return n == 0 ? std::string("none") : std::to_string(n);
  };
  std::printf("budget: %s Gaussians, %s surfels (%s), density: %s\n",
              budget_text(options.max_gaussians).c_str(), budget_text(options.max_surfels).c_str(),
              st->budget_why.c_str(), options.density.c_str());
  return Status::Ok();
}

Status ReconstructionPipeline::ChooseCoarseLevel(RunState* st) {
  if (options_.coarse_max_size < 0) return Status::Error("--coarse_max_size must be >= 0");
  SolverOptions& options = st->options;
  options.coarse_factor = CoarseFactor(st->scene, options_.coarse_max_size);
  if (options.coarse_factor <= 1 || options.coarse_fraction <= 0) return Status::Ok();
  const Camera& c = st->scene.views[st->scene.TrainIndices().front()].camera;
  // Coarsest first: "1/4 size (400x295), then 1/2 size (800x590)".
  std::string sizes;
  for (const int factor : options.CoarseFactors()) {
    const Camera coarse = CoarseCamera(c, factor);
    sizes += (sizes.empty() ? "" : ", then ") + std::string("1/") + std::to_string(factor) +
             " size (" + std::to_string(coarse.width) + "x" + std::to_string(coarse.height) + ")";
  }
  std::printf(
      "coarse start: the first %.0f%% of each stage at %s, then %dx%d "
      "(--coarse_max_size %d, --coarse_fraction %g, --coarse_levels %d)\n",
      100 * options.coarse_fraction, sizes.c_str(), c.width, c.height, options_.coarse_max_size,
      options.coarse_fraction, options.coarse_levels);
  return Status::Ok();
}

Status ReconstructionPipeline::ChooseMeshRegion(RunState* st) {
  // The mesh's region, from the cameras unless given.
  st->surface = options_.surface;
  MGSR_RETURN_IF_ERROR(
      ResolveMeshRegion(options_.mesh_region, st->scene, &st->surface, &st->region_note));
  std::printf("mesh region: %s\n", st->region_note.c_str());
  return Status::Ok();
}

Status ReconstructionPipeline::ChooseBatches(RunState* st) {
  const ReconstructionOptions& o = options_;
  SolverOptions& options = st->options;
  const size_t train_views = st->scene.TrainIndices().size();
  if (options.batch_views > static_cast<int>(train_views)) {
    return Status::Error("--batch_views " + std::to_string(options.batch_views) +
                         " is more than the " + std::to_string(train_views) +
                         " training views of " + st->workspace);
  }
  if (options.batch_views > 1) {
    if (o.batch_scale_iterations) {
      if (options.losses.empty()) options.losses = PaperLossTable(options);
      options.ScaleIterationsForBatch(options.batch_views);
    }
    std::printf("batches: %d views per step%s%s, %d process%s\n", options.batch_views,
                options.batch_sqrt_lr ? ", learning rates x sqrt(batch)" : "",
                o.batch_scale_iterations ? ", iteration counts / batch" : "",
                o.group != nullptr ? o.group->size() : 1,
                o.group != nullptr && o.group->size() > 1 ? "es" : "");
  }
  // The options are final from here on.
  return options.Validate();
}

Status ReconstructionPipeline::CreateSolver(RunState* st) {
  const ReconstructionOptions& o = options_;
  st->solver = std::make_unique<MutualBoostedSolver>(st->options, st->scene);
  MutualBoostedSolver& solver = *st->solver;
  if (o.group != nullptr) {
    // Processes that would not train the same model must not start: the same options (with the
    // scene's choices), the same views and cameras, the same checkpoint.
    for (const auto& [what, value] :
         {std::pair<std::string, std::string>{"options", solver.SettingsFingerprint()},
          {"scene", solver.SceneFingerprint()},
          {"--resume", o.resume ? FileSha256(st->ckpt) : ""}}) {
      MGSR_RETURN_IF_ERROR(o.group->CheckSame(what, value));
    }
    solver.SetViewGroup(o.group);
  }
  if (o.resume) {
    MGSR_RETURN_IF_ERROR(solver.LoadCheckpoint(st->ckpt));
    std::printf("resuming from %s\n", st->ckpt.c_str());
  }
  return Status::Ok();
}

Status ReconstructionPipeline::FollowOrCheck(RunState* st) {
  if (!st->writer) {
    st->stopped = true;
    return TrainAlongside(st->solver.get(), st->options, st->scene, st->surface, &st->end);
  }
  if (options_.check_only) {
    std::printf("check: the scene%s can be trained\n",
                options_.resume ? " and the checkpoint" : "");
    st->end = ReconstructionEnd::kChecked;
    st->stopped = true;
  }
  return Status::Ok();
}

Status ReconstructionPipeline::PrepareOutputs(RunState* st) {
  const ReconstructionOptions& o = options_;
  const SolverOptions& options = st->options;
  MutualBoostedSolver& solver = *st->solver;
  // The previous run's results go only now that the scene and the checkpoint are accepted.
  MGSR_RETURN_IF_ERROR(st->out.Prepare());
  MGSR_RETURN_IF_ERROR(MakeDirectories(st->out.Path("renders")));
  MGSR_RETURN_IF_ERROR(MakeDirectories(st->ckpt_dir));
  st->log = std::make_unique<ProgressLog>(st->out.Path("log.csv"), o.log_every, options, o.resume);
  MGSR_RETURN_IF_ERROR(st->log->Flush());
  solver.AddCallback(st->log.get());
  st->evaluation =
      std::make_unique<TestEvaluation>(&solver, st->scene, options.background_3d, o.eval_every);
  solver.AddCallback(st->evaluation.get());
  // A checkpoint every --checkpoint_every iterations, the log flushed with it.
  ProgressLog* log = st->log.get();
  st->checkpointer = std::make_unique<CheckpointCallback>(st->ckpt, o.checkpoint_every,
                                                          [log] { return log->Flush(); });
  solver.AddCallback(st->checkpointer.get());
  const Status found = FindGroundTruth(st->scene.root, &st->ground_truth);
  if (!found.ok())
    std::fprintf(stderr, "warning: ground truth not used: %s\n", found.message().c_str());
  if (st->ground_truth.found()) {
    st->gt_caster = std::make_unique<RayCaster>(st->ground_truth.mesh);
    st->gt_depth = std::make_unique<ExactDepthViews>(*st->gt_caster, TrainingCameras(st->scene));
  }
  st->depth_after_warmup =
      std::make_unique<DepthAfterWarmup>(&solver, options, st->scene, st->gt_depth.get(),
                                         JoinPath(st->ckpt_dir, "depth_after_warmup.json"));
  solver.AddCallback(st->depth_after_warmup.get());
  return Status::Ok();
}

Status ReconstructionPipeline::TrainModels(RunState* st) {
  MutualBoostedSolver& solver = *st->solver;
  const Status trained = Train(&solver, &st->summary);
  if (!trained.ok()) return st->checkpointer->status().ok() ? trained : st->checkpointer->status();
  if (st->summary.termination_type == TerminationType::kInterrupted) {
    // Ctrl-C: the state is at an iteration boundary; keep it.
    MGSR_RETURN_IF_ERROR(solver.SaveCheckpoint(st->ckpt));
    MGSR_RETURN_IF_ERROR(st->log->Flush());
    std::fprintf(stderr,
                 "interrupted %s: checkpoint written to %s; run again with --resume to "
                 "continue\n",
                 st->summary.message.c_str(), st->ckpt.c_str());
    st->end = ReconstructionEnd::kInterrupted;
    st->stopped = true;
    return Status::Ok();
  }
  std::printf("%s\n", st->summary.BriefReport().c_str());
  if (options_.profile) std::printf("%s", FormatProfile(st->summary.profile).c_str());
  std::fflush(stdout);  // the end of training shows at once, also when stdout is a file
  if (options_.checkpoint_every > 0) {
    // The finished state: --resume then skips training and only rebuilds the outputs (e.g. a mesh
    // with other fusion settings).
    MGSR_RETURN_IF_ERROR(solver.SaveCheckpoint(st->ckpt));
  }
  MGSR_RETURN_IF_ERROR(st->log->Flush());
  if (stop_requested_) return StopWriting(st);
  return Status::Ok();
}

Status ReconstructionPipeline::StopWriting(RunState* st) {
  // Ctrl-C while the outputs are written: the results so far are taken back and the finished
  // state is kept, so --resume writes them without training again.
  st->out.Discard();
  MGSR_RETURN_IF_ERROR(st->solver->SaveCheckpoint(st->ckpt));
  std::fprintf(stderr,
               "interrupted while writing the outputs: the results written so far are removed; "
               "the trained state is in %s: run again with --resume to write them\n",
               st->ckpt.c_str());
  st->end = ReconstructionEnd::kInterrupted;
  st->stopped = true;
  return Status::Ok();
}

Status ReconstructionPipeline::WriteModels(RunState* st) {
  const SolverOptions& options = st->options;
  const MutualBoostedSolver& solver = *st->solver;
  OutputFolder& out = st->out;
  // Models: only the branches this method trains (an untrained branch is its initialisation).
  if (options.train_2d) {
    MGSR_RETURN_IF_ERROR(WriteSurfelPly(out.Path("point_cloud_2d.ply"), solver.surfels()));
    MGSR_RETURN_IF_ERROR(out.Record("point_cloud_2d.ply"));
  }
  for (const std::string& format : options_.export_formats) {
    if (!options.train_3d) break;
    if (format == "glb") continue;  // the mesh's format, written with mesh.ply
    const std::string name = "point_cloud_3d." + format;
    if (format == "ply") MGSR_RETURN_IF_ERROR(WriteGaussianPly(out.Path(name), solver.gaussians()));
    if (format == "splat") MGSR_RETURN_IF_ERROR(WriteSplatFile(out.Path(name), solver.gaussians()));
    if (format == "spz") MGSR_RETURN_IF_ERROR(WriteSpzFile(out.Path(name), solver.gaussians()));
    MGSR_RETURN_IF_ERROR(out.Record(name));
  }
  // Learnt backgrounds (mgsr_render draws them behind new views).
  for (const Branch b : {Branch::kSurfels2D, Branch::kGaussians3D}) {
    const EnvironmentBackground* env = solver.environment(b);
    if (env == nullptr) continue;
    const std::string name = EnvironmentFileName(BranchName(b));
    MGSR_RETURN_IF_ERROR(WritePfm(out.Path(name), env->map().ToImage()));
    MGSR_RETURN_IF_ERROR(out.Record(name));
  }
  return Status::Ok();
}

Status ReconstructionPipeline::ScoreTestViews(RunState* st) {
  // Test views: PSNR / SSIM of the composite (3DGS, or 2DGS for the 2dgs method) against the
  // ground truth on its background, and the renders a person looks at.
  TestScores& t = st->test;
  t.views = st->scene.TestIndices();
  for (int i : t.views) {
    MGSR_RETURN_IF_ERROR(ScoreTestView(st, st->scene.views[i]));
    if (stop_requested_) return StopWriting(st);
  }
  if (!t.views.empty()) {
    const double n = t.views.size();
    t.psnr /= n;
    t.ssim /= n;
    t.psnr_aligned /= n;
    t.ssim_aligned /= n;
  }
  return Status::Ok();
}

Status ReconstructionPipeline::ScoreTestView(RunState* st, const View& v) {
  TestScores& t = st->test;
  OutputFolder& out = st->out;
  const ViewRender rendered = RenderView(st->solver.get(), st->options, v.camera);
  const Appearance& g = rendered.appearance;
  const Geometry& sr = rendered.geometry;
  const ScoredPair scored = ScoredImages(v, g.color, g.background);
  const Image& gt = scored.truth;
  const double p = std::min(100.0, Psnr(scored.render, gt)), q = Ssim(scored.render, gt);
  t.psnr += p;
  t.ssim += q;
  // Exposure-aligned: the test views' light and exposure are not predictable from the training
  // views.
  const AlignedScores aligned =
      ExposureAlignedScores(scored.render, gt, v.mask.empty() ? nullptr : &v.mask);
  // The object alone (where the mask is): comparable across framings of the same capture.
  const double foreground = v.mask.empty()
                                ? std::numeric_limits<double>::quiet_NaN()
                                : std::min(100.0, ForegroundPsnr(scored.render, gt, v.mask));
  if (std::isfinite(foreground)) {
    t.psnr_foreground += foreground;
    ++t.foreground_views;
  }
  t.psnr_aligned += std::min(100.0, aligned.psnr);
  t.ssim_aligned += aligned.ssim;
  const std::string stem = FileStem(v.name);
  // Each render is written and then recorded in the manifest.
  const auto write_render = [&out, &stem](const std::string& suffix, const Image& image) {
    const std::string name = "renders/" + stem + "_" + suffix + ".png";
    MGSR_RETURN_IF_ERROR(WriteImage(out.Path(name), image));
    return out.Record(name);
  };
  for (const auto& [suffix, image] :
       std::vector<std::pair<std::string, const Image*>>{{"composite", &g.color},
                                                         {"transmitted", &g.tran},
                                                         {"reflected", &g.ref},
                                                         {"weight", &g.weight},
                                                         {"gt", &gt}}) {
    MGSR_RETURN_IF_ERROR(write_render(suffix, *image));
  }
  // The same pictures as mgsr_render's: turbo-mapped depth over the object's own range, normals
  // as colours, black where nothing was rendered.
  MGSR_RETURN_IF_ERROR(write_render(
      "depth2d", DepthColormap(sr.depth, sr.alpha, RenderedDepthRange(sr.depth, sr.alpha))));
  MGSR_RETURN_IF_ERROR(write_render("normal2d", NormalColormap(sr.normal_world, sr.alpha)));
  t.per_view.push_back({{"name", v.name},
                        {"psnr", p},
                        {"ssim", q},
                        {"psnr_aligned", std::min(100.0, aligned.psnr)},
                        {"ssim_aligned", aligned.ssim}});
  if (std::isfinite(foreground)) t.per_view.back()["psnr_foreground"] = foreground;
  // Depth error against ground-truth depth maps when the scene has them (synthetic scenes);
  // the signed error map also from the exact depth of a ground-truth mesh (suzanne).
  Image gt_depth;
  const bool has_depth_map =
      ReadPfm(JoinPath(st->scene.root, "gt/depth/" + stem + ".pfm"), &gt_depth).ok() &&
      gt_depth.SameShape(sr.depth);
  if (!has_depth_map && st->gt_caster == nullptr) return Status::Ok();
  const Image truth = has_depth_map ? Image() : RenderExactDepth(*st->gt_caster, v.camera);
  MGSR_RETURN_IF_ERROR(write_render(
      "depth2d_error", SignedDepthErrorImage(sr.depth, has_depth_map ? gt_depth : truth, &v.mask,
                                             v.camera, kErrorMapFootprints)));
  if (!has_depth_map) return Status::Ok();
  double err = 0;
  int n = 0;
  for (size_t k = 0; k < gt_depth.size(); ++k) {
    if (gt_depth.data()[k] <= 0 || (!v.mask.empty() && v.mask.data()[k] < 0.5f)) continue;
    err += std::abs(sr.depth.data()[k] - gt_depth.data()[k]);
    ++n;
  }
  if (n > 0) {
    t.depth_error += err / n;
    ++t.depth_views;
  }
  return Status::Ok();
}

Status ReconstructionPipeline::ExtractMesh(RunState* st) {
  // Mesh: TSDF fusion of the geometry branch's depth over the training views (rendered at
  // --mesh_resolution_scale times their resolution), foreground and alpha >= 0.5, coloured by the
  // 3DGS transmitted (reflection-free) render (single-branch methods: that branch's depth and
  // colour).
  if (stop_requested_) return StopWriting(st);
  Timer mesh_timer;
  ProgressMeter mesh_progress("meshing", "views fused", 3.0, [](const std::string& line) {
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
  });
  Status s = ExtractSurface(
      st->solver.get(), st->options, st->scene, st->surface, &st->mesh,
      [&](int done, int total) { mesh_progress.Update(done, total); }, options_.group,
      &st->free_space);
  if (s.ok() && st->surface.free_space) {
    std::printf(
        "mesh free space: %zu of %zu vertices removed (more views see through them than "
        "hold them)\n",
        st->free_space.removed_vertices, st->free_space.vertices);
  }
  st->mesh_path = st->out.Path("mesh.ply");
  if (s.ok() && st->mesh.triangles.empty()) {
    s = Status::Error(st->mesh_path +
                      ": the fused mesh is empty (no rendered depth of the foreground reached the "
                      "fusion volume: check the cameras, the masks and the scene's scale)");
  }
  if (s.ok()) s = WriteTriangleMesh(st->mesh_path, st->mesh);
  if (s.ok()) s = st->out.Record("mesh.ply");
  const auto& formats = options_.export_formats;
  if (s.ok() && std::find(formats.begin(), formats.end(), "glb") != formats.end()) {
    s = WriteMeshGlb(st->out.Path("mesh.glb"), st->mesh);
    if (s.ok()) s = st->out.Record("mesh.glb");
  }
  if (!s.ok()) {
    const bool kept = FileExists(st->ckpt);
    return Status::Error(s.message() + (kept ? "; the trained state is kept in " + st->ckpt +
                                                   " (--resume rebuilds the outputs from it)"
                                             : ""));
  }
  st->mesh_seconds = mesh_timer.ElapsedSeconds();
  return Status::Ok();
}

nlohmann::json ReconstructionPipeline::MetricsJson(const RunState& st) const {
  const ReconstructionOptions& o = options_;
  const SolverOptions& options = st.options;
  const SolveSummary& summary = st.summary;
  const TestScores& t = st.test;
  nlohmann::json metrics = {
      {"scene", std::filesystem::absolute(st.workspace).lexically_normal().string()},
      {"preset", o.preset},
      {"method", o.method},
      {"mutual_mode", options.mutual_mode},
      {"surfel_low_pass", o.surfel_low_pass},
      {"surfel_filter_sigma", options.surfel_filter_sigma},
      {"surfel_init", o.surfel_init},
      {"losses", LossTableToJson(options.LossTable())["losses"]},
      {"seconds",
       {{"load", st.load_seconds},
        {"warmup", summary.warmup_seconds},
        {"mutual", summary.mutual_seconds},
        {"mesh", st.mesh_seconds},
        {"total", st.total.ElapsedSeconds()}}},
      {"peak_memory_mb", PeakMemoryBytes() / 1048576.0},
      // How the machine was used: threads, and how they waited (the tools spin briefly, 300
      // rounds, unless OMP_WAIT_POLICY or GOMP_SPINCOUNT is set).
      {"threads",
       {{"count", omp_get_max_threads()},
        {"omp_wait_policy", std::getenv("OMP_WAIT_POLICY") ? std::getenv("OMP_WAIT_POLICY") : ""},
        {"gomp_spincount", std::getenv("GOMP_SPINCOUNT") ? std::getenv("GOMP_SPINCOUNT") : ""}}},
      {"iterations",
       {{"warmup_2d", summary.branch(Branch::kSurfels2D).warmup_iterations},
        {"warmup_3d", summary.branch(Branch::kGaussians3D).warmup_iterations},
        {"auto_stopped_2d", summary.branch(Branch::kSurfels2D).auto_stopped},
        {"auto_stopped_3d", summary.branch(Branch::kGaussians3D).auto_stopped},
        {"mutual", summary.mutual_iterations},
        // Of those, the ones the 2DGS branch stepped in (SolverOptions::mutual_iterations_2d).
        {"mutual_2d", options.mutual_iterations_2d < 0
                          ? summary.mutual_iterations
                          : std::min(summary.mutual_iterations, options.mutual_iterations_2d)}}},
      {"counts",
       {{"gaussians", options.train_3d ? summary.branch(Branch::kGaussians3D).primitives : 0},
        {"surfels", options.train_2d ? summary.branch(Branch::kSurfels2D).primitives : 0}}},
      {"test",
       {{"views", t.views.size()},
        {"psnr", t.psnr},
        {"ssim", t.ssim},
        {"psnr_aligned", t.psnr_aligned},
        {"ssim_aligned", t.ssim_aligned},
        {"per_view", t.per_view}}},
      {"mesh",
       {{"path", st.mesh_path},
        {"vertices", st.mesh.vertices.size()},
        {"triangles", st.mesh.triangles.size()},
        {"resolution_scale", st.surface.resolution_scale},
        {"voxel_size", SurfaceTsdfOptions(st.scene, st.surface).voxel_size},
        {"region", st.region_note},
        {"free_space",
         {{"on", st.surface.free_space},
          {"vertices_removed", st.free_space.removed_vertices},
          {"triangles_removed", st.free_space.removed_triangles}}},
        {"pixel_footprint", TrainingFootprint(st.scene)}}}};
  if (!st.colmap_metrics.is_null()) metrics["colmap"] = st.colmap_metrics;
  if (o.profile) metrics["profile"] = ProfileToJson(summary.profile);
  metrics["budget"] = {{"gaussians", options.max_gaussians},
                       {"surfels", options.max_surfels},
                       {"mode", st.budget_mode},
                       {"why", st.budget_why},
                       {"density", options.density},
                       {"density_config", options.density_config},
                       {"spread_initial_surfels", options.spread_initial_surfels}};
  // The coarse start (factor 1: none): the last coarse iteration of each stage.
  metrics["coarse"] = {{"factor", options.coarse_factor},
                       {"levels", options.coarse_factor > 1 ? options.coarse_levels : 0},
                       {"factors", options.CoarseFactors()},
                       {"max_size", o.coarse_max_size},
                       {"fraction", options.coarse_fraction},
                       {"warmup_iterations", options.CoarseWarmupIterations()},
                       {"mutual_iterations", options.CoarseMutualIterations()}};
  metrics["background"] = {
      {"2d", options.background_2d}, {"3d", options.background_3d}, {"choice", st.background_note}};
  for (const Branch b : {Branch::kSurfels2D, Branch::kGaussians3D}) {
    if (st.solver->environment(b) != nullptr)
      metrics["background"]["environment"][BranchName(b)] = EnvironmentFileName(BranchName(b));
  }
  metrics["exposure"] = {{"mode", ExposureModeName(options.exposure)},
                         {"per_branch", options.exposure_per_branch},
                         {"fit_seconds", summary.exposure_fit_seconds}};
  if (options.exposure != ExposureMode::kOff) {
    // The learned transforms of the training views (the 3DGS branch's when per branch).
    nlohmann::json views = nlohmann::json::array();
    const ExposureModel& ex = st.solver->exposure(Branch::kGaussians3D);
    for (int v : st.scene.TrainIndices()) {
      const ColorTransform& p = ex.transform(v);
      views.push_back({{"name", st.scene.views[v].name},
                       {"matrix", std::vector<double>(p.begin(), p.begin() + 9)},
                       {"offset", std::vector<double>(p.begin() + 9, p.end())}});
    }
    metrics["exposure"]["views"] = views;
  }
  if (t.foreground_views > 0)
    metrics["test"]["psnr_foreground"] = t.psnr_foreground / t.foreground_views;
  if (t.depth_views > 0) {
    metrics["test"]["depth_abs_error"] = t.depth_error / t.depth_views;
    metrics["test"]["depth_abs_error_over_extent"] =
        t.depth_error / t.depth_views / st.scene.extent;
  }
  return metrics;
}

Status ReconstructionPipeline::WriteMetrics(RunState* st) {
  nlohmann::json metrics = MetricsJson(*st);
  if (st->ground_truth.found()) {
    const Status reported = ReportGeometry(st->solver.get(), st->options, st->scene,
                                           st->ground_truth, st->gt_depth.get(), st->surface,
                                           &st->mesh, st->depth_after_warmup->path(), &metrics);
    if (!reported.ok()) std::fprintf(stderr, "warning: %s\n", reported.message().c_str());
  }
  if (stop_requested_) return StopWriting(st);
  const TestScores& t = st->test;
  if (t.views.empty()) {
    // No held-out view: no image score at all, rather than a 0 that reads like a measurement.
    metrics["test"] = {{"views", 0},
                       {"note", "no test views (--test_every 0 and no split file): no PSNR/SSIM"}};
  }
  // Last: the manifest of every file this run wrote, so metrics.json vouches for the folder.
  metrics["files"] = st->out.Manifest();
  MGSR_RETURN_IF_ERROR(st->out.Write("metrics.json", metrics.dump(2) + "\n"));
  st->out.Commit();
  if (t.views.empty()) {
    std::printf("test views: none (--test_every 0 and no split file), so no PSNR/SSIM");
  } else {
    std::printf("test views: PSNR %.2f dB, SSIM %.4f (exposure-aligned %.2f dB, %.4f)", t.psnr,
                t.ssim, t.psnr_aligned, t.ssim_aligned);
  }
  if (t.depth_views > 0)
    std::printf(", 2DGS depth error %.4f (%.3f%% of the extent)", t.depth_error / t.depth_views,
                100 * t.depth_error / t.depth_views / st->scene.extent);
  std::printf("\nmesh: %s (%zu triangles); metrics: %s; total %.0f s\n", st->mesh_path.c_str(),
              st->mesh.triangles.size(), st->out.Path("metrics.json").c_str(),
              st->total.ElapsedSeconds());
  st->end = ReconstructionEnd::kFinished;
  return Status::Ok();
}

}  // namespace mgsr
