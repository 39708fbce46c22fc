// mgsr_solve: the main job. Reads a COLMAP workspace or a Blender folder, reconstructs it with both
// branches (warm-up with auto-stop, then the mutual stage), and writes the models, test-view
// renders, the TSDF mesh, a training log and metrics.json into --output.
#include <gflags/gflags.h>

#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>

#include "mgsr/core/timer.h"
#include "mgsr/eval/exposure_alignment.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/eval/metrics_json.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/io/output_folder.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/eval/ground_truth.h"
#include "mgsr/synth/ray_caster.h"
#include "solvers/backdrop.h"
#include "solvers/checkpoint_callback.h"
#include "solvers/density_control.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/surface_extraction.h"
#include "solvers/trained_views.h"
#include "tools/colmap_flags.h"
#include "tools/tool_flags.h"

DEFINE_string(workspace, "",
              "COLMAP workspace (images/, sparse/0/) or Blender folder (transforms_*.json).");
DEFINE_string(images, "",
              "Instead of --workspace: a folder of photos; colmap recovers the poses first "
              "(into OUTPUT/colmap), see mgsr_colmap.");
DEFINE_string(masks, "", "With --images: optional folder of foreground masks (<stem>.png).");
DEFINE_string(output, "", "Output folder (created).");
DEFINE_string(preset, "fast", "fast | paper: iteration counts and schedules.");
DEFINE_string(method, "mgsr",
              "mgsr (both branches) | 2dgs (the 2DGS branch alone) | 3dgs (plain 3DGS alone, no "
              "reflection) | 3dgs-ref (the 3DGS branch with reflection, alone).");
DEFINE_int32(downscale, 1, "Divide the input resolution by this factor.");
DEFINE_int32(max_width, 1600, "Cap the image width after downscaling (0: no cap).");
DEFINE_int32(test_every, 8,
             "Without a split file, every Nth image (by name) is held out (0: none).");
DEFINE_uint64(seed, 0, "Seed for every random choice.");
DEFINE_string(mutual_mode, "alternate", "alternate (the paper) | joint (the authors' code).");
DEFINE_string(surfel_low_pass, "area",
              "2DGS screen low-pass floor: area (its opacity scaled by the surfel's projected "
              "area: no silhouette dilation) | reference (2DGS: full opacity).");
DEFINE_double(surfel_filter_sigma, 0.29,
              "Sigma of the 2DGS screen low-pass in pixels (the reference: 0.707). Wider dilates "
              "silhouettes more, which pulls the surface in.");
DEFINE_string(surfel_init, "neighbours",
              "Initial 2DGS disk orientation: neighbours (in the plane of each initial point's 16 "
              "nearest points) | random (the reference).");
DEFINE_int32(warmup_max_iterations, -1, "Cap of warm-up iterations per branch (-1: preset).");
DEFINE_int32(warmup_min_iterations, -1, "Auto-stop only after this iteration (-1: preset).");
DEFINE_int32(mutual_iterations, -1, "Mutual-stage iterations (-1: preset).");
DEFINE_bool(auto_stop, true, "Stop each warm-up when its loss window flattens.");
DEFINE_bool(bidirectional, false,
            "Ablation K: the supervising branch also learns from the supervision.");
DEFINE_int64(max_gaussians, -1,
             "Budget of 3DGS primitives (-1: 4 per pixel of a training view, at least 500,000; "
             "0: none).");
DEFINE_int64(max_surfels, -1,
             "Budget of 2DGS primitives (-1: 4 per pixel of a training view, at least 500,000; "
             "0: none).");
DEFINE_double(w_2d, 0.5, "Weight of the 2DGS loss in the mutual stage.");
DEFINE_double(w_3d, 0.5, "Weight of the 3DGS loss in the mutual stage.");
DEFINE_double(w_depth, 0.01, "Weight of the mutual depth loss.");
DEFINE_double(lambda_l1, 0.8, "Render loss: lambda L1 + (1 - lambda) D-SSIM.");
DEFINE_double(lambda_normal, 2.0,
              "Weight of the normal consistency and normal TV terms (the reference: 0.05).");
DEFINE_double(depth_tv_warmup_2d, 1.0,
              "Weight of the 2DGS branch's edge-aware depth TV in its warm-up.");
DEFINE_double(depth_tv_mutual_2d, 0.05,
              "Weight of the 2DGS branch's edge-aware depth TV in the mutual stage.");
DEFINE_string(loss_config, "",
              "JSON file that changes rows of the loss table or adds rows (solvers/loss_table.h; "
              "--list_losses prints the terms and the table).");
DEFINE_bool(list_losses, false,
            "Print the registered loss terms and the loss table these options give, then exit.");
DEFINE_double(lambda_distortion, -1,
              "Weight of the 2DGS depth-distortion term (-1: the default of SolverOptions).");
DEFINE_double(
    mutual_transmitted_weight, 0.2,
    "2DGS mutual loss: weight of the render loss against the 3DGS transmitted image (lambda_6).");
DEFINE_string(exposure, "affine",
              "Per-view exposure compensation: off | diag (gain + offset per channel) | affine "
              "(3x3 colour matrix + offsets).");
DEFINE_double(exposure_lr, 5e-3, "Learning rate of the per-view colour transforms.");
DEFINE_double(exposure_prior, 1e-3, "Weight of the prior pulling each colour matrix to identity.");
DEFINE_double(exposure_offset_prior, 1.0, "Weight of the prior pulling each offset to zero.");
DEFINE_double(exposure_mean_prior, 10.0,
              "Weight of the prior pulling the mean transform over the views to identity (so "
              "novel views render at the photos' average exposure).");
DEFINE_bool(exposure_per_branch, false,
            "Separate colour transforms for the 2DGS and 3DGS branches (default: shared).");
DEFINE_bool(exposure_fit, true,
            "Re-fit every view's transform with Ceres (Huber) when the mutual stage starts.");
DEFINE_string(background, "auto",
              "Grey level the branches render on: auto (masked photos: 2DGS white, 3DGS black as in "
              "the reference; photos without masks: their backdrop's grey when it is uniform), "
              "reference, or a level in [0, 1] for both branches.");
DEFINE_int32(auto_stop_window, -1, "Auto-stop window in iterations (-1: preset).");
DEFINE_double(auto_stop_range, 0.01,
              "Auto-stop when max - min of the window's losses falls below this.");
DEFINE_int32(log_every, 100, "Print progress every N iterations.");
DEFINE_int32(eval_every, 500, "Print the test-view PSNR every N iterations (0: only at the end).");
DEFINE_string(mesh_depth, "expected",
              "Depth fused into the mesh: expected (MGSR) | median (2DGS).");
DEFINE_string(mesh_color, "transmitted",
              "Mesh colours: transmitted (3DGS, reflection-free) | surfel (2DGS render).");
DEFINE_double(voxel_size, 0,
              "TSDF voxel (0: the pixel footprint at the object / --mesh_resolution_scale).");
DEFINE_int32(mesh_resolution_scale, 1,
             "Render the depth for fusion at this many times the training resolution (the voxel "
             "follows the finer footprint).");
DEFINE_double(tsdf_truncation, 4, "TSDF truncation band in training pixel footprints.");
DEFINE_int32(checkpoint_every, 500,
             "Write OUTPUT/checkpoints/latest.ckpt every N iterations (0: only on Ctrl-C).");
DEFINE_bool(resume, false,
            "Continue from OUTPUT/checkpoints/latest.ckpt (same options and scene).");
DEFINE_bool(check, false,
            "Only load and check the scene (and with --resume the checkpoint), print what was "
            "found and exit: 0 when a run could start. Writes nothing; --output is optional.");
DEFINE_bool(overwrite, false,
            "Replace a previous run in --output (its results, checkpoints and log); without it "
            "a non-empty output folder is refused.");

namespace {

mgsr::MutualBoostedSolver* g_solver = nullptr;
volatile std::sig_atomic_t g_interrupted = 0;

void OnSigint(int) {
  g_interrupted = 1;
  if (g_solver != nullptr) g_solver->RequestStop();
}

// Test-view PSNR of the 3DGS composite every N iterations (after a 3DGS step, when the renderer's
// state is free to reuse).
class TestEvaluation : public mgsr::IterationCallback {
 public:
  TestEvaluation(mgsr::MutualBoostedSolver* solver, const mgsr::Scene& scene, int every)
      : solver_(solver), scene_(scene), every_(every) {}
  mgsr::CallbackReturnType operator()(const mgsr::IterationInfo& i) override {
    if (every_ <= 0 || i.branch != mgsr::Branch::kGaussians3D || i.iteration % every_ != 0) return mgsr::CallbackReturnType::kContinue;
    const auto test = scene_.TestIndices();
    if (test.empty()) return mgsr::CallbackReturnType::kContinue;
    double psnr = 0;
    for (int v : test) {
      mgsr::GaussianRender r;
      solver_->RenderGaussians(scene_.views[v].camera, &r);
      const mgsr::Image gt = mgsr::CompositeOnBackground(scene_.views[v], 0.0f);
      psnr += std::min(100.0, mgsr::Psnr(r.color, gt));
    }
    std::printf("[%s %5d] test PSNR %.2f dB (%zu views)\n",
                i.stage == mgsr::Stage::kWarmup ? "warmup" : "mutual", i.iteration,
                psnr / test.size(), test.size());
    std::fflush(stdout);
    return mgsr::CallbackReturnType::kContinue;
  }

 private:
  mgsr::MutualBoostedSolver* solver_;
  const mgsr::Scene& scene_;
  int every_;
};

int Fail(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

std::string DepthLine(const char* label, const mgsr::DepthErrorStats& d) {
  char line[200];
  std::snprintf(line, sizeof(line),
                "%s median %+.4f (%+.2f px), mean %+.4f, %.1f%% of pixels beyond 1 px", label,
                d.median, d.median_footprints, d.mean, 100 * d.share_beyond_footprint);
  return line;
}

// Signed depth error of the 2DGS branch on the training views when the warm-up ends (at the first
// mutual 2DGS step), against the ground truth. Written beside the checkpoint so a resumed run still
// reports it.
class DepthAfterWarmup : public mgsr::IterationCallback {
 public:
  DepthAfterWarmup(mgsr::MutualBoostedSolver* solver, const mgsr::SolverOptions& options,
                   const mgsr::Scene& scene, const mgsr::RayCaster* ground_truth, std::string path)
      : solver_(solver), options_(options), scene_(scene), gt_(ground_truth), path_(std::move(path)) {}
  mgsr::CallbackReturnType operator()(const mgsr::IterationInfo& i) override {
    if (gt_ == nullptr || done_ || i.stage != mgsr::Stage::kMutual ||
        i.branch != mgsr::Branch::kSurfels2D || i.iteration != 1)
      return mgsr::CallbackReturnType::kContinue;
    done_ = true;
    const mgsr::SurfaceDepthReport r = mgsr::MeasureSurfaceDepth(solver_, options_, scene_, *gt_);
    std::printf("%s\n%s\n", DepthLine("depth after warm-up (train views): expected", r.expected).c_str(),
                DepthLine("                                    median  ", r.median).c_str());
    const nlohmann::json j = {{"expected", mgsr::DepthErrorToJson(r.expected)},
                              {"median", mgsr::DepthErrorToJson(r.median)}};
    const mgsr::Status s = mgsr::WriteStringToFileAtomic(path_, j.dump(2) + "\n");
    if (!s.ok()) std::fprintf(stderr, "warning: %s\n", s.message().c_str());
    return mgsr::CallbackReturnType::kContinue;
  }
  const std::string& path() const { return path_; }

 private:
  mgsr::MutualBoostedSolver* solver_;
  const mgsr::SolverOptions& options_;
  const mgsr::Scene& scene_;
  const mgsr::RayCaster* gt_;
  std::string path_;
  bool done_ = false;
};

// Everything the ground truth lets us say about the geometry: the mesh's exact metrics beside the
// exact-depth ceiling of the same cameras and fusion (and of the training resolution when fusing
// finer), and the signed depth error after the warm-up and at the end.
mgsr::Status ReportGeometry(mgsr::MutualBoostedSolver* solver, const mgsr::SolverOptions& options,
                            const mgsr::Scene& scene, const mgsr::GroundTruthGeometry& gt,
                            const mgsr::RayCaster& gt_caster, const mgsr::SurfaceOptions& surface, const mgsr::TriangleMesh* mesh,
                            const std::string& warmup_depth_path, nlohmann::json* metrics) {
  const double footprint = mgsr::TrainingFootprint(scene);
  mgsr::MeshMetricsOptions mo;
  mo.pixel_footprint = footprint;
  if (!gt.visible_path.empty()) mo.completeness_points = &gt.visible_points;
  nlohmann::json& out = (*metrics)["mesh"];
  out["ground_truth"] = gt.mesh_path;
  if (!gt.visible_path.empty()) out["completeness_points"] = gt.visible_path;
  auto line = [&](const char* label, const mgsr::MeshMetrics& m) {
    std::printf("%s NC x100 %.2f, CD x1000 %.3f, signed offset %+.4f (%+.2f px, %.0f%% inside), "
                "F-score at 1 px %.3f\n",
                label, 100 * m.normal_consistency, 1000 * m.chamfer, m.signed_offset_median,
                m.signed_offset_median / footprint, 100 * m.fraction_inside,
                m.FScoreAtFootprints(1.0));
  };
  if (mesh != nullptr) {
    const mgsr::MeshMetrics m = mgsr::EvaluateMesh(*mesh, gt.mesh, mo);
    out.update(mgsr::MeshMetricsToJson(m));
    line("mesh vs ground truth:   ", m);
  }
  mgsr::TriangleMesh ceiling;
  MGSR_RETURN_IF_ERROR(mgsr::ExactDepthCeiling(gt.mesh, scene, surface, &ceiling));
  const mgsr::MeshMetrics c = mgsr::EvaluateMesh(ceiling, gt.mesh, mo);
  out["ceiling"] = mgsr::MeshMetricsToJson(c);
  line("exact-depth ceiling:    ", c);
  if (surface.resolution_scale != 1) {
    mgsr::SurfaceOptions one = surface;
    one.resolution_scale = 1;
    MGSR_RETURN_IF_ERROR(mgsr::ExactDepthCeiling(gt.mesh, scene, one, &ceiling));
    const mgsr::MeshMetrics c1 = mgsr::EvaluateMesh(ceiling, gt.mesh, mo);
    out["ceiling_1x"] = mgsr::MeshMetricsToJson(c1);
    line("ceiling at 1x:          ", c1);
  }
  const mgsr::SurfaceDepthReport d = mgsr::MeasureSurfaceDepth(solver, options, scene, gt_caster);
  (*metrics)["depth"]["end"] = {{"expected", mgsr::DepthErrorToJson(d.expected)},
                                {"median", mgsr::DepthErrorToJson(d.median)}};
  std::printf("%s\n%s\n", DepthLine("depth at the end (train views): expected", d.expected).c_str(),
              DepthLine("                                median  ", d.median).c_str());
  std::string text;
  if (mgsr::ReadFileToString(warmup_depth_path, &text).ok()) {
    try {
      (*metrics)["depth"]["after_warmup"] = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception&) {
      // A damaged side file only loses this figure.
    }
  }
  return mgsr::Status::Ok();
}

// Progress lines and log.csv rows.
class ProgressLog : public mgsr::IterationCallback {
 public:
  // A progress line follows each step of the last branch of a round (the 3DGS branch, or the 2DGS
  // branch when it trains alone); an untrained branch shows as "-".
  ProgressLog(const std::string& csv_path, int every, int expected_total, bool append,
              bool train_2d, bool train_3d)
      : path_(csv_path),
        every_(every),
        expected_(expected_total),
        train_2d_(train_2d),
        train_3d_(train_3d) {
    // A resumed run continues the log; a missing or empty one (peek fails alike) starts with its
    // header.
    const bool header =
        !append || std::ifstream(csv_path).peek() == std::ifstream::traits_type::eof();
    csv_.open(csv_path, append ? std::ios::app : std::ios::trunc);
    if (header) csv_ << "stage,iteration,branch,loss,gaussians,surfels,seconds,terms\n";
  }
  // The rows so far reach the disk (at every checkpoint, so a killed run loses none it resumes
  // from); an error names the file.
  mgsr::Status Flush() {
    csv_.flush();
    if (!csv_) return mgsr::Status::Error(path_ + ": cannot write the training log");
    return mgsr::Status::Ok();
  }
  mgsr::CallbackReturnType operator()(const mgsr::IterationInfo& i) override {
    const bool is2d = i.branch == mgsr::Branch::kSurfels2D;
    const char* stage = i.stage == mgsr::Stage::kWarmup ? "warmup" : "mutual";
    csv_ << stage << "," << i.iteration << "," << (is2d ? "2dgs" : "3dgs") << "," << i.loss << ","
         << i.num_gaussians << "," << i.num_surfels << "," << i.seconds << ",";
    // The loss table's active rows: name=weight x value, separated by ';'.
    for (size_t k = 0; k < i.terms.size(); ++k) {
      csv_ << (k ? ";" : "") << i.terms[k].name << "=" << i.terms[k].weight * i.terms[k].value;
    }
    csv_ << "\n";
    (is2d ? loss_2d_ : loss_3d_) = i.loss;
    ++steps_;
    if (i.iteration % every_ == 0 && is2d != train_3d_) {
      const double eta = steps_ > 0 ? i.seconds / steps_ * std::max(0, expected_ - steps_) : 0;
      const std::string loss_2d = train_2d_ ? Format("%.4f", loss_2d_) : "-";
      const std::string loss_3d = train_3d_ ? Format("%.4f", loss_3d_) : "-";
      const std::string surfels = train_2d_ ? std::to_string(i.num_surfels) : "-";
      const std::string gaussians = train_3d_ ? std::to_string(i.num_gaussians) : "-";
      std::printf("[%s %5d] loss 2DGS %s 3DGS %s | surfels %s Gaussians %s | %.0f s, ~%.0f s left\n",
                  stage, i.iteration, loss_2d.c_str(), loss_3d.c_str(), surfels.c_str(),
                  gaussians.c_str(), i.seconds, eta);
      std::fflush(stdout);
    }
    return mgsr::CallbackReturnType::kContinue;
  }

 private:
  std::string path_;
  std::ofstream csv_;
  static std::string Format(const char* format, double v) {
    char buffer[32];
    std::snprintf(buffer, sizeof(buffer), format, v);
    return buffer;
  }

  int every_, expected_, steps_ = 0;
  bool train_2d_, train_3d_;
  double loss_2d_ = 0, loss_3d_ = 0;
};

mgsr::Image Colorize(const mgsr::Image& one, float lo, float hi) {
  mgsr::Image out(one.width(), one.height(), 1);
  for (size_t i = 0; i < one.size(); ++i)
    out.data()[i] = hi > lo ? (one.data()[i] - lo) / (hi - lo) : 0.0f;
  return out;
}

// --background is "auto", "reference" or a grey level in [0, 1] (returned in `level`, else -1).
// Checked with the other options, before any scene is loaded or colmap runs.
mgsr::Status ParseBackground(const std::string& flag, double* level) {
  *level = -1;
  if (flag == "auto" || flag == "reference") return mgsr::Status::Ok();
  char* end = nullptr;
  const double v = std::strtod(flag.c_str(), &end);
  if (end == flag.c_str() || *end != '\0' || !(v >= 0 && v <= 1)) {
    return mgsr::Status::Error("--background must be auto, reference or a grey level in [0, 1], "
                               "not '" + flag + "'");
  }
  *level = v;
  return mgsr::Status::Ok();
}

// Sets both branches' backgrounds from a parsed --background; returns what was chosen and why.
std::string ChooseBackground(const std::string& flag, double level, const mgsr::Scene& scene,
                             mgsr::SolverOptions* o) {
  if (level >= 0) {
    o->background_2d = o->background_3d = static_cast<float>(level);
    return "grey " + flag + " (both branches, --background)";
  }
  if (flag == "auto") {
    const mgsr::Backdrop b = mgsr::EstimateBackdrop(scene);
    if (b.uniform) {
      o->background_2d = o->background_3d = b.level;
      return "the photos' uniform backdrop, grey " + std::to_string(b.level) + " (both branches)";
    }
    return "reference (2DGS white, 3DGS black): " + b.reason;
  }
  return "reference (2DGS white, 3DGS black)";
}

// --list_losses: the registry's terms with the buffers they read, then the table.
void PrintLosses(const mgsr::SolverOptions& options) {
  std::printf("Registered loss terms (name: differentiated inputs [constant inputs]):\n");
  for (const std::string& name : mgsr::LossRegistry::Get().Names()) {
    mgsr::Status status;
    const auto term = mgsr::LossRegistry::Get().Create(name, nlohmann::json::object(), &status);
    std::string inputs, constants;
    if (term != nullptr) {
      for (mgsr::Buffer b : term->Inputs()) inputs += std::string(" ") + mgsr::BufferName(b);
      for (mgsr::Buffer b : term->ConstantInputs())
        constants += std::string(" ") + mgsr::BufferName(b);
    }
    std::printf("  %-20s%s%s\n", name.c_str(), inputs.c_str(),
                constants.empty() ? "" : (" [" + constants.substr(1) + "]").c_str());
  }
  std::printf("\nThe loss table of these options (--loss_config FILE changes or adds rows):\n");
  std::printf("  %-6s %-7s %-20s %-19s %10s %6s  %s\n", "branch", "stage", "name", "term", "weight",
              "from", "config");
  for (const mgsr::LossSpec& r : options.LossTable()) {
    std::printf("  %-6s %-7s %-20s %-19s %10.4g %6d  %s%s\n", mgsr::BranchName(r.branch),
                mgsr::StageName(r.stage), r.name.c_str(), r.term.c_str(), r.weight,
                std::max(1, r.first_iteration), r.config.dump().c_str(),
                r.exposure ? " (behind the view's colour transform)" : "");
  }
}

}  // namespace

int main(int argc, char** argv) {
  mgsr_tools::ParseToolFlags(
      "mgsr_solve (--workspace DIR | --images DIR [--masks DIR]) --output DIR [--preset "
      "fast|paper] [options]",
      {{"Input", {"workspace", "images", "masks", "downscale", "max_width", "test_every",
                  "background"}},
       {"Photos to cameras (with --images)", {"colmap", "per_image_cameras", "camera_model",
                                              "exhaustive_max_images", "max_image_size"}},
       {"Output and run control", {"output", "overwrite", "resume", "check", "checkpoint_every",
                                   "log_every", "eval_every"}},
       {"Method and schedule", {"preset", "method", "mutual_mode", "warmup_max_iterations",
                                "warmup_min_iterations", "mutual_iterations", "auto_stop",
                                "auto_stop_window", "auto_stop_range", "bidirectional", "seed"}},
       {"Losses", {"loss_config", "list_losses", "lambda_l1", "lambda_normal",
                   "lambda_distortion", "depth_tv_warmup_2d", "depth_tv_mutual_2d", "w_2d",
                   "w_3d", "w_depth", "mutual_transmitted_weight"}},
       {"Exposure compensation", {"exposure", "exposure_lr", "exposure_prior",
                                  "exposure_offset_prior", "exposure_mean_prior",
                                  "exposure_per_branch", "exposure_fit"}},
       {"Primitives", {"max_gaussians", "max_surfels", "surfel_low_pass", "surfel_filter_sigma",
                       "surfel_init"}},
       {"Mesh", {"mesh_depth", "mesh_color", "voxel_size", "mesh_resolution_scale",
                 "tsdf_truncation"}}},
      &argc, &argv);
  const bool listing = FLAGS_list_losses;  // needs no scene
  if (!listing && FLAGS_workspace.empty() == FLAGS_images.empty()) {
    std::fprintf(stderr, "error: give either --workspace or --images\n");
    return 2;
  }
  if (!listing && !FLAGS_masks.empty() && FLAGS_images.empty()) {
    std::fprintf(stderr, "error: --masks goes with --images (a workspace has its own masks/)\n");
    return 2;
  }
  if (!listing && FLAGS_output.empty() && !(FLAGS_check && !FLAGS_resume)) {
    std::fprintf(stderr, "error: --output is required\n");
    return 2;
  }
  if (FLAGS_check && !FLAGS_images.empty()) {
    std::fprintf(stderr, "error: --check goes with --workspace (--images would run colmap)\n");
    return 2;
  }
  mgsr::SolverOptions options;
  if (!mgsr::SolverOptions::FromPreset(FLAGS_preset, &options))
    return Fail("unknown --preset '" + FLAGS_preset + "' (fast or paper)");
  options.mutual_mode = FLAGS_mutual_mode;
  if (FLAGS_surfel_low_pass != "area" && FLAGS_surfel_low_pass != "reference")
    return Fail("--surfel_low_pass must be area or reference");
  options.surfel_area_preserving_low_pass = FLAGS_surfel_low_pass == "area";
  options.surfel_filter_sigma = static_cast<float>(FLAGS_surfel_filter_sigma);
  if (FLAGS_surfel_init != "neighbours" && FLAGS_surfel_init != "random")
    return Fail("--surfel_init must be neighbours or random");
  options.surfel_orientation_from_points = FLAGS_surfel_init == "neighbours";
  if (FLAGS_warmup_max_iterations >= 0) options.warmup_max_iterations = FLAGS_warmup_max_iterations;
  if (FLAGS_warmup_min_iterations >= 0) options.warmup_min_iterations = FLAGS_warmup_min_iterations;
  if (FLAGS_mutual_iterations >= 0) options.mutual_iterations = FLAGS_mutual_iterations;
  if (!mgsr::SolverOptions::ApplyMethod(FLAGS_method, &options))
    return Fail("unknown --method '" + FLAGS_method + "' (mgsr, 2dgs, 3dgs or 3dgs-ref)");
  options.auto_stop = FLAGS_auto_stop;
  options.bidirectional = FLAGS_bidirectional;
  if (FLAGS_max_gaussians < -1 || FLAGS_max_surfels < -1)
    return Fail("--max_gaussians and --max_surfels must be -1 (from the scene), 0 (none) or a count");
  options.w_2d = FLAGS_w_2d;
  options.w_3d = FLAGS_w_3d;
  options.w_depth = FLAGS_w_depth;
  options.lambda_l1 = FLAGS_lambda_l1;
  options.lambda_normal = FLAGS_lambda_normal;
  options.depth_tv_warmup_2d = FLAGS_depth_tv_warmup_2d;
  options.depth_tv_mutual_2d = FLAGS_depth_tv_mutual_2d;
  if (FLAGS_lambda_distortion >= 0) {
    options.lambda_distortion = FLAGS_lambda_distortion;
  } else if (FLAGS_lambda_distortion != -1) {
    return Fail("--lambda_distortion must be >= 0 (or -1 for the default)");
  }
  options.mutual_transmitted_weight = FLAGS_mutual_transmitted_weight;
  options.mutual_image_weight = 1.0 - FLAGS_mutual_transmitted_weight;
  if (FLAGS_auto_stop_window >= 0) options.auto_stop_window = FLAGS_auto_stop_window;
  options.auto_stop_range = FLAGS_auto_stop_range;
  options.seed = FLAGS_seed;
  {
    const mgsr::Status e = mgsr::ParseExposureMode(FLAGS_exposure, &options.exposure);
    if (!e.ok()) return Fail(e.message());
  }
  options.exposure_lr = FLAGS_exposure_lr;
  options.exposure_prior = FLAGS_exposure_prior;
  options.exposure_offset_prior = FLAGS_exposure_offset_prior;
  options.exposure_mean_prior = FLAGS_exposure_mean_prior;
  options.exposure_per_branch = FLAGS_exposure_per_branch;
  options.exposure_fit_at_mutual = FLAGS_exposure_fit;
  if (FLAGS_log_every < 1) return Fail("--log_every must be >= 1");
  if (FLAGS_mesh_depth != "expected" && FLAGS_mesh_depth != "median")
    return Fail("--mesh_depth must be expected or median");
  if (FLAGS_mesh_color != "transmitted" && FLAGS_mesh_color != "surfel")
    return Fail("--mesh_color must be transmitted or surfel");
  if (!(FLAGS_voxel_size >= 0)) return Fail("--voxel_size must be >= 0");
  if (FLAGS_mesh_resolution_scale < 1 || FLAGS_mesh_resolution_scale > 8)
    return Fail("--mesh_resolution_scale must be between 1 and 8");
  if (!(FLAGS_tsdf_truncation > 0)) return Fail("--tsdf_truncation must be > 0");
  if (FLAGS_checkpoint_every < 0) return Fail("--checkpoint_every must be >= 0");
  if (FLAGS_eval_every < 0) return Fail("--eval_every must be >= 0");
  double background_level = -1;
  {
    const mgsr::Status b = ParseBackground(FLAGS_background, &background_level);
    if (!b.ok()) return Fail(b.message());
  }
  if (!FLAGS_loss_config.empty()) {
    options.losses = options.LossTable();
    const mgsr::Status l = mgsr::ApplyLossConfigFile(FLAGS_loss_config, &options.losses);
    if (!l.ok()) return Fail(l.message());
  }
  const mgsr::Status valid = options.Validate();
  if (!valid.ok()) return Fail(valid.message());
  if (listing) {
    PrintLosses(options);
    return 0;
  }
  if (FLAGS_resume && FLAGS_overwrite) {
    std::fprintf(stderr, "error: --resume and --overwrite exclude each other\n");
    return 2;
  }
  const std::string ckpt_dir = mgsr::JoinPath(FLAGS_output, "checkpoints");
  const std::string ckpt = mgsr::JoinPath(ckpt_dir, "latest.ckpt");
  if (FLAGS_resume && !mgsr::FileExists(ckpt)) return Fail(ckpt + ": no checkpoint to resume from");
  mgsr::OutputFolder out;
  if (!FLAGS_check) {
    const mgsr::Status opened = mgsr::OutputFolder::Open(
        FLAGS_output,
        FLAGS_resume      ? mgsr::OutputMode::kResume
        : FLAGS_overwrite ? mgsr::OutputMode::kOverwrite
                          : mgsr::OutputMode::kFresh,
        &out);
    if (!opened.ok()) return Fail(opened.message());
  }
  // From here on a failure takes back the results it wrote: no folder looks finished unless it is.
  const auto fail = [&out](const std::string& message) {
    out.Discard();
    return Fail(message);
  };

  mgsr::Timer total;
  nlohmann::json colmap_metrics;
  if (!FLAGS_images.empty()) {
    mgsr::ColmapPipelineOptions co = mgsr_tools::ColmapOptionsFromFlags();
    co.images = FLAGS_images;
    co.masks = FLAGS_masks;
    co.workspace = mgsr::JoinPath(FLAGS_output, "colmap");
    const std::string dense = mgsr::JoinPath(co.workspace, "dense");
    if (FLAGS_resume && mgsr::DirectoryExists(mgsr::JoinPath(dense, "sparse"))) {
      std::printf("colmap: reusing %s (--resume)\n", dense.c_str());
    } else {
      const mgsr::Status prepared = out.Prepare();  // colmap writes into the output folder
      if (!prepared.ok()) return fail(prepared.message());
      mgsr::ColmapPipelineSummary cs;
      const mgsr::Status ran = mgsr::RunColmapPipeline(co, &cs);
      if (!ran.ok()) return fail(ran.message());
      mgsr_tools::PrintColmapSummary(cs);
      colmap_metrics = {{"images_given", cs.images_given},
                        {"images_registered", cs.images_registered},
                        {"unregistered", cs.unregistered},
                        {"points", cs.points},
                        {"mean_reprojection_error_px", cs.mean_reprojection_error}};
      for (const auto& step : cs.steps) colmap_metrics["seconds"][step.name] = step.seconds;
    }
    FLAGS_workspace = dense;
  }
  mgsr::Timer load_timer;
  mgsr::SceneOptions so;
  so.downscale = FLAGS_downscale;
  so.max_width = FLAGS_max_width;
  so.test_every = FLAGS_test_every;
  so.seed = FLAGS_seed;
  mgsr::Scene scene;
  mgsr::Status s = mgsr::LoadScene(FLAGS_workspace, so, &scene);
  if (!s.ok()) return fail(s.message());
  for (const std::string& w : scene.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
  const double load_seconds = load_timer.ElapsedSeconds();
  const mgsr::Camera& cam0 = scene.views.front().camera;
  std::printf("scene: %s (%s), %zu train / %zu test views, %dx%d, %zu points, masks: %s\n",
              FLAGS_workspace.c_str(), scene.source.c_str(), scene.TrainIndices().size(),
              scene.TestIndices().size(), cam0.width, cam0.height, scene.points.size(),
              scene.has_masks() ? "yes" : "no (gamma = 1, mesh not masked)");

  const std::string background_note =
      ChooseBackground(FLAGS_background, background_level, scene, &options);
  std::printf("background: %s\n", background_note.c_str());
  const size_t scene_budget = mgsr::DefaultPrimitiveBudget(scene);
  options.max_gaussians = FLAGS_max_gaussians < 0 ? scene_budget : FLAGS_max_gaussians;
  options.max_surfels = FLAGS_max_surfels < 0 ? scene_budget : FLAGS_max_surfels;
  const auto budget_text = [](size_t n) { return n == 0 ? std::string("none") : std::to_string(n); };
  std::printf("budget: %s Gaussians, %s surfels%s\n", budget_text(options.max_gaussians).c_str(),
              budget_text(options.max_surfels).c_str(),
              FLAGS_max_gaussians < 0 || FLAGS_max_surfels < 0
                  ? " (4 per pixel of a training view, at least 500,000, unless given)"
                  : "");

  mgsr::MutualBoostedSolver solver(options, scene);
  if (FLAGS_resume) {
    s = solver.LoadCheckpoint(ckpt);
    if (!s.ok()) return fail(s.message());
    std::printf("resuming from %s\n", ckpt.c_str());
  }
  if (FLAGS_check) {
    std::printf("check: the scene%s can be trained\n",
                FLAGS_resume ? " and the checkpoint" : "");
    return 0;
  }
  // The previous run's results go only now that the scene and the checkpoint are accepted.
  s = out.Prepare();
  if (s.ok()) s = mgsr::MakeDirectories(out.Path("renders"));
  if (s.ok()) s = mgsr::MakeDirectories(ckpt_dir);
  if (!s.ok()) return fail(s.message());
  const int trained_branches = (options.train_2d ? 1 : 0) + (options.train_3d ? 1 : 0);
  ProgressLog log(out.Path("log.csv"), FLAGS_log_every,
                  trained_branches * options.warmup_max_iterations +
                      (options.mutual_mode == "joint" ? 2 : 1) * options.mutual_iterations,
                  FLAGS_resume, options.train_2d, options.train_3d);
  s = log.Flush();
  if (!s.ok()) return fail(s.message());
  solver.AddCallback(&log);
  TestEvaluation evaluation(&solver, scene, FLAGS_eval_every);
  solver.AddCallback(&evaluation);
  // A checkpoint every --checkpoint_every iterations, the log flushed with it.
  mgsr::CheckpointCallback checkpointer(ckpt, FLAGS_checkpoint_every, [&log] { return log.Flush(); });
  solver.AddCallback(&checkpointer);
  mgsr::GroundTruthGeometry ground_truth;
  s = mgsr::FindGroundTruth(scene.root, &ground_truth);
  if (!s.ok()) std::fprintf(stderr, "warning: ground truth not used: %s\n", s.message().c_str());
  std::unique_ptr<mgsr::RayCaster> gt_caster;
  if (ground_truth.found()) gt_caster = std::make_unique<mgsr::RayCaster>(ground_truth.mesh);
  DepthAfterWarmup depth_after_warmup(&solver, options, scene, gt_caster.get(),
                                      mgsr::JoinPath(ckpt_dir, "depth_after_warmup.json"));
  solver.AddCallback(&depth_after_warmup);
  g_solver = &solver;
  std::signal(SIGINT, OnSigint);
  mgsr::SolveSummary summary;
  s = solver.Solve(&summary);
  if (!s.ok()) return fail(checkpointer.status().ok() ? s.message() : checkpointer.status().message());
  if (summary.termination_type == mgsr::TerminationType::kInterrupted) {
    // Ctrl-C: the state is at an iteration boundary; keep it.
    s = solver.SaveCheckpoint(ckpt);
    if (s.ok()) s = log.Flush();
    if (!s.ok()) return fail(s.message());
    std::fprintf(stderr, "interrupted %s: checkpoint written to %s; run again with --resume to "
                 "continue\n", summary.message.c_str(), ckpt.c_str());
    return 130;
  }
  g_solver = nullptr;
  std::printf("%s\n", summary.BriefReport().c_str());
  std::fflush(stdout);  // the end of training shows at once, also when stdout is a file
  if (FLAGS_checkpoint_every > 0) {
    // The finished state: --resume then skips training and only rebuilds the outputs (e.g. a mesh
    // with other fusion settings).
    s = solver.SaveCheckpoint(ckpt);
    if (!s.ok()) return fail(s.message());
  }
  s = log.Flush();
  if (!s.ok()) return fail(s.message());
  // Ctrl-C while the outputs are written: the results so far are taken back and the finished
  // state is kept, so --resume writes them without training again.
  const auto stop_writing = [&]() {
    out.Discard();
    const mgsr::Status saved = solver.SaveCheckpoint(ckpt);
    if (!saved.ok()) return fail(saved.message());
    std::fprintf(stderr,
                 "interrupted while writing the outputs: the results written so far are removed; "
                 "the trained state is in %s: run again with --resume to write them\n",
                 ckpt.c_str());
    return 130;
  };
  if (g_interrupted) return stop_writing();

  // Models: only the branches this method trains (an untrained branch is its initialisation).
  if (options.train_2d) {
    s = mgsr::WriteSurfelPly(out.Path("point_cloud_2d.ply"), solver.surfels());
    if (s.ok()) s = out.Record("point_cloud_2d.ply");
  }
  if (s.ok() && options.train_3d) {
    s = mgsr::WriteGaussianPly(out.Path("point_cloud_3d.ply"), solver.gaussians());
    if (s.ok()) s = out.Record("point_cloud_3d.ply");
  }
  if (!s.ok()) return fail(s.message());

  // Test views: PSNR / SSIM of the composite (3DGS, or 2DGS for the 2dgs method) against the
  // ground truth on its background, and the renders a person looks at.
  mgsr::Timer eval_timer;
  double psnr = 0, ssim = 0, psnr_aligned = 0, ssim_aligned = 0, depth_err = 0;
  int depth_views = 0;
  const auto test = scene.TestIndices();
  nlohmann::json per_view = nlohmann::json::array();
  for (int i : test) {
    const mgsr::View& v = scene.views[i];
    mgsr::ViewRender rendered = mgsr::RenderView(&solver, options, v.camera);
    const mgsr::Appearance& g = rendered.appearance;
    const mgsr::Geometry& sr = rendered.geometry;
    const mgsr::Image gt = mgsr::CompositeOnBackground(v, g.background);
    const double p = std::min(100.0, mgsr::Psnr(g.color, gt)), q = mgsr::Ssim(g.color, gt);
    psnr += p;
    ssim += q;
    // Exposure-aligned: the test views' light and exposure are not predictable from the training
    // views.
    const mgsr::AlignedScores aligned =
        mgsr::ExposureAlignedScores(g.color, gt, v.mask.empty() ? nullptr : &v.mask);
    psnr_aligned += std::min(100.0, aligned.psnr);
    ssim_aligned += aligned.ssim;
    const std::string stem = mgsr::FileStem(v.name);
    // Each render is written and then recorded in the manifest.
    const auto write_render = [&out, &stem](const std::string& suffix, const mgsr::Image& image) {
      const std::string name = "renders/" + stem + "_" + suffix + ".png";
      mgsr::Status w = mgsr::WriteImage(out.Path(name), image);
      if (w.ok()) w = out.Record(name);
      return w;
    };
    float dmin = 1e30f, dmax = 0;
    for (size_t k = 0; k < sr.depth.size(); ++k) {
      if (sr.alpha.data()[k] < 0.5f) continue;
      dmin = std::min(dmin, sr.depth.data()[k]);
      dmax = std::max(dmax, sr.depth.data()[k]);
    }
    mgsr::Image normal(sr.normal_world.width(), sr.normal_world.height(), 3);
    for (size_t k = 0; k < normal.size(); ++k)
      normal.data()[k] = 0.5f + 0.5f * sr.normal_world.data()[k];
    for (const auto& [suffix, image] :
         std::vector<std::pair<std::string, const mgsr::Image*>>{{"composite", &g.color},
                                                                 {"transmitted", &g.tran},
                                                                 {"reflected", &g.ref},
                                                                 {"weight", &g.weight},
                                                                 {"gt", &gt}}) {
      s = write_render(suffix, *image);
      if (!s.ok()) return fail(s.message());
    }
    s = write_render("depth2d", Colorize(sr.depth, dmin, dmax));
    if (s.ok()) s = write_render("normal2d", normal);
    if (!s.ok()) return fail(s.message());
    if (g_interrupted) return stop_writing();
    // Depth error against ground-truth depth maps when the scene has them (synthetic scenes).
    mgsr::Image gt_depth;
    double err = 0;
    int n = 0;
    if (mgsr::ReadPfm(mgsr::JoinPath(scene.root, "gt/depth/" + stem + ".pfm"), &gt_depth).ok() &&
        gt_depth.SameShape(sr.depth)) {
      for (size_t k = 0; k < gt_depth.size(); ++k) {
        if (gt_depth.data()[k] <= 0 || (!v.mask.empty() && v.mask.data()[k] < 0.5f)) continue;
        err += std::abs(sr.depth.data()[k] - gt_depth.data()[k]);
        ++n;
      }
      if (n > 0) {
        depth_err += err / n;
        ++depth_views;
      }
    }
    per_view.push_back({{"name", v.name},
                        {"psnr", p},
                        {"ssim", q},
                        {"psnr_aligned", std::min(100.0, aligned.psnr)},
                        {"ssim_aligned", aligned.ssim}});
  }
  if (!test.empty()) {
    psnr /= test.size();
    ssim /= test.size();
    psnr_aligned /= test.size();
    ssim_aligned /= test.size();
  }

  // Mesh: TSDF fusion of the geometry branch's depth over the training views (rendered at
  // --mesh_resolution_scale times their resolution), foreground and alpha >= 0.5, coloured by the
  // 3DGS transmitted (reflection-free) render (single-branch methods: that branch's depth and
  // colour).
  if (g_interrupted) return stop_writing();
  mgsr::Timer mesh_timer;
  mgsr::SurfaceOptions surface;
  surface.resolution_scale = FLAGS_mesh_resolution_scale;
  surface.median_depth = FLAGS_mesh_depth == "median";
  surface.surfel_color = FLAGS_mesh_color == "surfel";
  surface.voxel_size = FLAGS_voxel_size;
  surface.truncation_voxels = FLAGS_tsdf_truncation;
  mgsr::TriangleMesh mesh;
  s = mgsr::ExtractSurface(&solver, options, scene, surface, &mesh);
  const std::string mesh_path = out.Path("mesh.ply");
  if (s.ok() && mesh.triangles.empty()) {
    s = mgsr::Status::Error(
        mesh_path + ": the fused mesh is empty (no rendered depth of the foreground reached the "
                    "fusion volume: check the cameras, the masks and the scene's scale)");
  }
  if (s.ok()) s = mgsr::WriteTriangleMesh(mesh_path, mesh);
  if (s.ok()) s = out.Record("mesh.ply");
  if (!s.ok()) {
    const bool kept = mgsr::FileExists(ckpt);
    return fail(s.message() + (kept ? "; the trained state is kept in " + ckpt +
                                          " (--resume rebuilds the outputs from it)"
                                    : ""));
  }
  const double mesh_seconds = mesh_timer.ElapsedSeconds();

  nlohmann::json metrics = {{"scene", FLAGS_workspace},
                            {"preset", FLAGS_preset},
                            {"method", FLAGS_method},
                            {"mutual_mode", options.mutual_mode},
                            {"surfel_low_pass", FLAGS_surfel_low_pass},
                            {"surfel_filter_sigma", options.surfel_filter_sigma},
                            {"surfel_init", FLAGS_surfel_init},
                            {"losses", mgsr::LossTableToJson(options.LossTable())["losses"]},
                            {"seconds",
                             {{"load", load_seconds},
                              {"warmup", summary.warmup_seconds},
                              {"mutual", summary.mutual_seconds},
                              {"mesh", mesh_seconds},
                              {"total", total.ElapsedSeconds()}}},
                            {"peak_memory_mb", mgsr::PeakMemoryBytes() / 1048576.0},
                            {"iterations",
                             {{"warmup_2d", summary.branch(mgsr::Branch::kSurfels2D).warmup_iterations},
                              {"warmup_3d", summary.branch(mgsr::Branch::kGaussians3D).warmup_iterations},
                              {"auto_stopped_2d", summary.branch(mgsr::Branch::kSurfels2D).auto_stopped},
                              {"auto_stopped_3d", summary.branch(mgsr::Branch::kGaussians3D).auto_stopped},
                              {"mutual", summary.mutual_iterations}}},
                            {"counts",
                             {{"gaussians", options.train_3d ? summary.branch(mgsr::Branch::kGaussians3D).primitives : 0},
                              {"surfels", options.train_2d ? summary.branch(mgsr::Branch::kSurfels2D).primitives : 0}}},
                            {"test",
                             {{"views", test.size()},
                              {"psnr", psnr},
                              {"ssim", ssim},
                              {"psnr_aligned", psnr_aligned},
                              {"ssim_aligned", ssim_aligned},
                              {"per_view", per_view}}},
                            {"mesh",
                             {{"path", mesh_path},
                              {"vertices", mesh.vertices.size()},
                              {"triangles", mesh.triangles.size()},
                              {"resolution_scale", surface.resolution_scale},
                              {"voxel_size", mgsr::SurfaceTsdfOptions(scene, surface).voxel_size},
                              {"pixel_footprint", mgsr::TrainingFootprint(scene)}}}};
  if (!colmap_metrics.is_null()) metrics["colmap"] = colmap_metrics;
  metrics["budget"] = {{"gaussians", options.max_gaussians},
                       {"surfels", options.max_surfels},
                       {"from_scene", FLAGS_max_gaussians < 0 || FLAGS_max_surfels < 0}};
  metrics["background"] = {{"2d", options.background_2d},
                           {"3d", options.background_3d},
                           {"choice", background_note}};
  metrics["exposure"] = {{"mode", mgsr::ExposureModeName(options.exposure)},
                         {"per_branch", options.exposure_per_branch},
                         {"fit_seconds", summary.exposure_fit_seconds}};
  if (options.exposure != mgsr::ExposureMode::kOff) {
    // The learned transforms of the training views (the 3DGS branch's when per branch).
    nlohmann::json views = nlohmann::json::array();
    const mgsr::ExposureModel& ex = solver.exposure(mgsr::Branch::kGaussians3D);
    for (int v : scene.TrainIndices()) {
      const mgsr::ColorTransform& p = ex.transform(v);
      views.push_back({{"name", scene.views[v].name},
                       {"matrix", std::vector<double>(p.begin(), p.begin() + 9)},
                       {"offset", std::vector<double>(p.begin() + 9, p.end())}});
    }
    metrics["exposure"]["views"] = views;
  }
  if (depth_views > 0) {
    metrics["test"]["depth_abs_error"] = depth_err / depth_views;
    metrics["test"]["depth_abs_error_over_extent"] = depth_err / depth_views / scene.extent;
  }
  if (ground_truth.found()) {
    const mgsr::Status reported =
        ReportGeometry(&solver, options, scene, ground_truth, *gt_caster, surface,
                       &mesh,
                       depth_after_warmup.path(), &metrics);
    if (!reported.ok()) std::fprintf(stderr, "warning: %s\n", reported.message().c_str());
  }
  if (g_interrupted) return stop_writing();
  // Last: the manifest of every file this run wrote, so metrics.json vouches for the folder.
  metrics["files"] = out.Manifest();
  s = out.Write("metrics.json", metrics.dump(2) + "\n");
  if (!s.ok()) return fail(s.message());
  std::printf("test views: PSNR %.2f dB, SSIM %.4f (exposure-aligned %.2f dB, %.4f)", psnr, ssim,
              psnr_aligned, ssim_aligned);
  if (depth_views > 0)
    std::printf(", 2DGS depth error %.4f (%.3f%% of the extent)", depth_err / depth_views,
                100 * depth_err / depth_views / scene.extent);
  std::printf("\nmesh: %s (%zu triangles); metrics: %s; total %.0f s\n", mesh_path.c_str(),
              mesh.triangles.size(), out.Path("metrics.json").c_str(),
              total.ElapsedSeconds());
  return 0;
}
