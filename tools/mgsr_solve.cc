// mgsr_solve: the main job. Reads a COLMAP workspace or a Blender folder, reconstructs it with both
// branches (warm-up with auto-stop, then the mutual stage), and writes the models, test-view
// renders, the TSDF mesh, a training log and metrics.json into --output.
#include <gflags/gflags.h>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>

#include "mgsr/core/timer.h"
#include "mgsr/eval/exposure_alignment.h"
#include "mgsr/eval/ground_truth.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/eval/metrics_json.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/io/output_folder.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/io/splat_formats.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/synth/ray_caster.h"
#include "solvers/backdrop.h"
#include "solvers/checkpoint_callback.h"
#include "solvers/density_control.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/primitive_prior.h"
#include "solvers/reconstruction_pipeline.h"
#include "solvers/surface_extraction.h"
#include "solvers/trained_views.h"
#include "solvers/view_group.h"
#include "tools/colmap_flags.h"
#include "tools/openmp_wait.h"
#include "tools/tool_flags.h"
#ifdef MGSR_WITH_MPI
#include "solvers/mpi_view_group.h"
#endif

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
DEFINE_int32(max_size, 1600,
             "Cap the images' long side after downscaling, keeping the aspect (0: no cap).");
DEFINE_int32(max_width, 0, "Also cap the image width after downscaling (0: no cap).");
DEFINE_int32(test_every, 8,
             "Without a split file, every Nth image (by name) is held out (0: none).");
DEFINE_int32(far_points, 0,
             "Unbounded captures: add this many initial points on a sphere far around the "
             "cameras (far background and sky beyond the SfM points).");
DEFINE_double(far_radius, 10, "Radius of the --far_points sphere in scene extents.");
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
DEFINE_string(surfel_spread, "masked",
              "Initial 2DGS disks: masked (the default: on where every view has a mask or alpha, "
              "off otherwise) | on (the points spread over their own surfaces to the 2DGS budget: "
              "smaller first disks, which recover grooves and slots of detailed objects; without "
              "masks a backdrop's small disks scatter, docs/geometry.md) | off (one per initial "
              "point, the reference).");
DEFINE_int32(warmup_max_iterations, -1, "Cap of warm-up iterations per branch (-1: preset).");
DEFINE_int32(warmup_min_iterations, -1, "Auto-stop only after this iteration (-1: preset).");
DEFINE_int32(mutual_iterations, -1, "Mutual-stage iterations (-1: preset).");
DEFINE_int32(mutual_iterations_2d, -2,
             "The 2DGS branch steps in the first N mutual iterations only, then is held while the "
             "3DGS branch trains on (-1: the whole stage; default: fast's 1,500 where the views "
             "have masks and the stage is longer, else the whole stage).");
DEFINE_int32(position_lr_max_steps, -1,
             "The position learning rate decays over this many iterations of each stage: the "
             "3DGS branch's, and the 2DGS branch's unless --position_lr_max_steps_2d (-1: "
             "preset, fast 2250, paper the reference's 30000).");
DEFINE_int32(position_lr_max_steps_2d, -1,
             "The 2DGS branch's own decay (-1: preset, paper 2250, fast the same as "
             "--position_lr_max_steps; the reference's is 30000).");
DEFINE_bool(surfel_shape_decay, false,
            "In a stage longer than the 2DGS position decay (paper's mutual stage), the 2DGS "
            "scale and rotation rates then decay the same way, so the surfels' shape settles: "
            "steadier large surfaces under changing light, shallower grooves.");
DEFINE_int32(coarse_max_size, 800,
             "Coarse start: views longer than this train the first part of each stage "
             "(--coarse_fraction) downscaled by the smallest integer that fits them (0: always "
             "full size).");
DEFINE_double(coarse_fraction, 0.75,
              "Coarse start: the share of each stage's iterations (of the warm-up cap, of the "
              "mutual stage) on the downscaled views.");
DEFINE_int32(coarse_levels, 1,
             "Coarse start (1-8): that share is split evenly among this many levels, coarsest "
             "first, each half the size of the next (2: a quarter of the --coarse_max_size fit, "
             "then the fit; faster, and a little less accurate: docs/performance.md).");
DEFINE_bool(auto_stop, true, "Stop each warm-up when its loss window flattens.");
DEFINE_bool(bidirectional, false,
            "Ablation K: the supervising branch also learns from the supervision.");
DEFINE_int32(batch_views, 1,
             "Training views per step: their gradients are summed and the step taken once. Under "
             "mpirun (a build with -DMGSR_WITH_MPI=ON) the processes share each batch: a power "
             "of two that divides it.");
DEFINE_bool(batch_sqrt_lr, true, "With --batch_views B > 1: the learning rates grow by sqrt(B).");
DEFINE_bool(batch_keep_iterations, false,
            "With --batch_views B > 1: keep the iteration counts (each step then sees B views); "
            "by default they are divided by B, so the run sees as many views as with B = 1.");
DEFINE_string(budget, "",
              "Primitive budget of each branch: auto (from the object's size in pixels: 180 "
              "Gaussians and 135 surfels x sqrt(foreground pixels of the median view)) | scene (4 "
              "per pixel of a view, at least 500,000: a bound, not a "
              "target) | none | a count. Empty: the density strategy's default (mcmc: auto, "
              "reference: scene).");
DEFINE_int64(max_gaussians, -1, "Budget of 3DGS primitives (-1: from --budget; 0: none).");
DEFINE_int64(max_surfels, -1, "Budget of 2DGS primitives (-1: from --budget; 0: none).");
DEFINE_string(density, "mcmc",
              "Density strategy of both branches: mcmc (relocation under a fixed budget, "
              "Kheradmand et al. 2024; with --budget auto by default) | reference "
              "(clone/split/prune, the authors').");
DEFINE_string(density_config, "",
              "JSON config of the density strategy, e.g. '{\"growth\": 0.05}' for mcmc "
              "(keys: dead_opacity, growth, noise_lr, opacity_reg, scale_reg).");
DEFINE_double(prune_contribution, 0,
              "At the end of each stage, drop primitives whose blend weights summed over every "
              "pixel of every training view stay below this (0: off).");
DEFINE_double(w_2d, 0.5, "Weight of the 2DGS loss in the mutual stage.");
DEFINE_double(w_3d, 0.5, "Weight of the 3DGS loss in the mutual stage.");
DEFINE_double(w_depth, 0.01, "Weight of the mutual depth loss.");
DEFINE_double(lambda_l1, 0.8, "Render loss: lambda L1 + (1 - lambda) D-SSIM.");
DEFINE_double(lambda_normal, -1,
              "Weight of the normal consistency term; -1: 2.0 where the views have masks or "
              "alpha, the reference's 0.05 where they have neither.");
DEFINE_double(lambda_normal_tv, 0.05,
              "Weight of the 2DGS branch's edge-aware normal TV (the reference's 0.05), "
              "independent of --lambda_normal.");
DEFINE_double(depth_tv_warmup_2d, -1,
              "Weight of the 2DGS branch's edge-aware depth TV in its warm-up; -1: the "
              "reference's 1.0, or 0 for a scene in the world (learnt background; then the 3DGS "
              "depth TV is off too).");
DEFINE_double(depth_tv_mutual_2d, -1,
              "Weight of the 2DGS branch's edge-aware depth TV in the mutual stage; -1: the "
              "reference's 0.05, or 0 for a scene in the world (learnt background).");
DEFINE_bool(tv_on_geometry, false,
            "The depth and normal TVs only between pixels a branch covers (rendered alpha), not "
            "across a silhouette or a horizon to the backdrop or sky.");
DEFINE_bool(depth_tv_disparity, false,
            "The depth TVs on the disparity s^2 / D (s: the cameras' distance to the object) "
            "instead of D: no pull on planes seen in perspective (a receding ground).");
DEFINE_string(loss_config, "",
              "JSON file that changes rows of the loss table or adds rows (solvers/loss_table.h; "
              "--list_losses prints the terms and the table).");
DEFINE_bool(list_losses, false,
            "Print the registered loss terms and the loss table these options give, then exit.");
DEFINE_double(lambda_distortion, -1,
              "Weight of the 2DGS depth-distortion term (-1: from the scene: 1000 where no mask or "
              "alpha tells the object from its backdrop, else 0 as in the reference).");
DEFINE_double(lambda_mask, -1,
              "Weight of the 2DGS silhouette term: binary cross-entropy of the rendered alpha "
              "against the foreground mask (no effect without masks; -1: 3 where every training "
              "view has a mask or alpha).");
DEFINE_double(lambda_mask_warmup, -1,
              "Weight of the silhouette term in the warm-up alone (-1: --lambda_mask's). 10 "
              "recovers deep grooves and slots of detailed objects at some cost on smooth ones "
              "(docs/geometry.md, \"The silhouette's weight by stage\").");
DEFINE_double(lambda_multiview_ncc, -1,
              "Weight of the 2DGS multi-view patch NCC through the rendered plane (-1: the "
              "default of SolverOptions).");
DEFINE_double(lambda_multiview_depth, -1,
              "Weight of the 2DGS multi-view forward-backward depth reprojection (-1: the "
              "default).");
DEFINE_double(
    lambda_surfel_layer, -1,
    "Weight of the surfel layer prior: overlapping 2DGS disks that face the same way "
    "pulled onto one sheet (solvers/surfel_layer_prior.h). -1: 10 where the initial disks "
    "are spread (--surfel_spread), else 0 (docs/geometry.md, \"A layer of disks\").");
DEFINE_double(
    lambda_normal_mutual, -1,
    "Weight of the normal consistency in the mutual stage (before w_2d); -1: --lambda_normal's.");
DEFINE_bool(normal_depth_gradient, true,
            "The normal consistency also pulls the depth (false: only the rendered normals turn "
            "towards the depth's).");
DEFINE_double(normal_edge_weight, -1,
              "The normal consistency relaxes where the photo has edges: weight exp(-beta x "
              "gradient) per pixel (0: off; -1: the default of SolverOptions).");
DEFINE_double(normal_robust_scale, -1,
              "The normal consistency's residual r enters as s r / (r + s): pixels whose depth "
              "normal disagrees strongly (creases, steps) stop smoothing the depth (0: off; -1: "
              "the default of SolverOptions).");
DEFINE_bool(
    normal_one_sided, false,
    "At depth steps (one neighbour's jump over 3x the other's) the normal consistency takes "
    "the depth's normal from the one-sided difference towards the closer neighbour (not given: "
    "on where every training view has a mask or alpha).");
DEFINE_double(normal_agreement_floor, -1,
              "The normal consistency's weight falls towards this fraction where the neighbouring "
              "photos agree with the rendered plane (patch NCC), and keeps its full weight where "
              "they cannot place the surface (1: off; -1: the default of SolverOptions).");
DEFINE_int32(multiview_neighbours, 2, "Neighbouring views per view for the multi-view terms.");
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
DEFINE_string(
    background, "auto",
    "What the branches render on: auto (masked photos: 2DGS white, 3DGS black as in the "
    "reference; photos without masks: their backdrop's grey when it is uniform, else env), "
    "reference, env (a background per viewing direction, learnt: sky and far background of a "
    "scene), or a grey level in [0, 1] for both branches.");
DEFINE_int32(auto_stop_window, -1, "Auto-stop window in iterations (-1: preset).");
DEFINE_double(auto_stop_range, 0.01,
              "Auto-stop when max - min of the window's losses falls below this.");
DEFINE_int32(log_every, 100, "Print progress every N iterations.");
DEFINE_bool(profile, false,
            "Time every stage of an iteration (projection, binning, raster forward/backward, "
            "losses, Adam, density control, exposure) and print ms per iteration per stage and "
            "branch after training (also metrics.json \"profile\").");
DEFINE_int32(eval_every, 500, "Print the test-view PSNR every N iterations (0: only at the end).");
DEFINE_string(export, "ply",
              "Output formats, comma-separated: ply (point_cloud_3d.ply, every attribute), "
              "splat (32 bytes a splat), spz (Niantic's compressed format): the 3DGS model, the "
              "last two with the transmitted colour only; glb: the mesh also as binary glTF "
              "(mesh.glb; mesh.ply is always written).");
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
DEFINE_string(mesh_region, "auto",
              "What the mesh covers: auto (where half the training cameras' view frusta meet; "
              "far background and sky stay out), none (everything the depth reaches), a box "
              "x0,y0,z0,x1,y1,z1, or a JSON file with \"min\" and \"max\" (mgsr_synth's "
              "gt/region.json).");
DEFINE_bool(mesh_free_space, true,
            "Remove the parts of the fused mesh that more training views see through (render "
            "nothing at, or see well behind) than hold at their depth (docs/geometry.md, \"Free "
            "space\").");
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

mgsr::ReconstructionPipeline* g_pipeline = nullptr;

void OnSigint(int) {
  if (g_pipeline != nullptr) g_pipeline->RequestStop();
}

// "MPI process N: " on the processes of an MPI job other than process 0 (whose errors, often
// the same as process 0's, would otherwise read like a repeat of it).
std::string g_error_prefix;

int Fail(const std::string& message) {
  std::fprintf(stderr, "%serror: %s\n", g_error_prefix.c_str(), message.c_str());
  return 1;
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
  std::printf(
      "\nRegistered priors on the primitives (rows evaluated on the model, not a render):\n");
  for (const std::string& name : mgsr::PriorRegistry::Get().Names())
    std::printf("  %s\n", name.c_str());
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

int Main(int argc, char** argv, mgsr::ViewGroup* group) {
  mgsr_tools::ParseToolFlags(
      "mgsr_solve (--workspace DIR | --images DIR [--masks DIR]) --output DIR [--preset "
      "fast|paper] [options]",
      {{"Input",
        {"workspace", "images", "masks", "downscale", "max_size", "max_width", "test_every",
         "background", "far_points", "far_radius"}},
       {"Photos to cameras (with --images)",
        {"colmap", "per_image_cameras", "camera_model", "exhaustive_max_images", "max_image_size"}},
       {"Output and run control",
        {"output", "overwrite", "resume", "check", "checkpoint_every", "log_every", "eval_every",
         "profile"}},
       {"Method and schedule",
        {"preset", "method", "mutual_mode", "warmup_max_iterations", "warmup_min_iterations",
         "mutual_iterations", "mutual_iterations_2d", "position_lr_max_steps",
         "position_lr_max_steps_2d", "surfel_shape_decay", "auto_stop", "auto_stop_window",
         "auto_stop_range", "bidirectional", "coarse_max_size", "coarse_fraction", "coarse_levels",
         "seed"}},
       {"Batches and MPI", {"batch_views", "batch_sqrt_lr", "batch_keep_iterations"}},
       {"Losses",
        {"loss_config",
         "list_losses",
         "lambda_l1",
         "lambda_normal",
         "lambda_normal_tv",
         "lambda_distortion",
         "lambda_mask",
         "lambda_mask_warmup",
         "lambda_multiview_ncc",
         "lambda_multiview_depth",
         "multiview_neighbours",
         "lambda_surfel_layer",
         "normal_depth_gradient",
         "normal_edge_weight",
         "normal_robust_scale",
         "normal_one_sided",
         "normal_agreement_floor",
         "lambda_normal_mutual",
         "depth_tv_warmup_2d",
         "depth_tv_mutual_2d",
         "tv_on_geometry",
         "depth_tv_disparity",
         "w_2d",
         "w_3d",
         "w_depth",
         "mutual_transmitted_weight"}},
       {"Exposure compensation",
        {"exposure", "exposure_lr", "exposure_prior", "exposure_offset_prior",
         "exposure_mean_prior", "exposure_per_branch", "exposure_fit"}},
       {"Primitives",
        {"density", "density_config", "budget", "prune_contribution", "max_gaussians",
         "max_surfels", "surfel_low_pass", "surfel_filter_sigma", "surfel_init", "surfel_spread"}},
       {"Models", {"export"}},
       {"Mesh",
        {"mesh_depth", "mesh_color", "voxel_size", "mesh_resolution_scale", "tsdf_truncation",
         "mesh_region", "mesh_free_space"}}},
      &argc, &argv);
  const bool listing = FLAGS_list_losses;  // needs no scene
  mgsr::ReconstructionOptions ro;
  ro.workspace = FLAGS_workspace;
  ro.images = FLAGS_images;
  ro.masks = FLAGS_masks;
  ro.output = FLAGS_output;
  ro.overwrite = FLAGS_overwrite;
  ro.resume = FLAGS_resume;
  ro.check_only = FLAGS_check;
  if (!listing) {
    const mgsr::Status usage = ro.CheckInputsAndOutput();
    if (!usage.ok()) {
      std::fprintf(stderr, "error: %s\n", usage.message().c_str());
      return 2;
    }
  }
  mgsr::SolverOptions& options = ro.solver;
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
  if (FLAGS_surfel_spread != "masked" && FLAGS_surfel_spread != "on" &&
      FLAGS_surfel_spread != "off")
    return Fail("--surfel_spread must be off, on or masked");
  ro.spread_from_scene = FLAGS_surfel_spread == "masked";
  options.spread_initial_surfels = FLAGS_surfel_spread == "on";
  // -1 means "the preset's"; any other negative count is a typo, not a request.
  for (const auto& [value, name] :
       {std::pair{FLAGS_warmup_max_iterations, "--warmup_max_iterations"},
        std::pair{FLAGS_warmup_min_iterations, "--warmup_min_iterations"},
        std::pair{FLAGS_mutual_iterations, "--mutual_iterations"}}) {
    if (value < -1) return Fail(std::string(name) + " must be >= 0 (or -1 for the preset's)");
  }
  for (const auto& [value, name] :
       {std::pair{FLAGS_position_lr_max_steps, "--position_lr_max_steps"},
        std::pair{FLAGS_position_lr_max_steps_2d, "--position_lr_max_steps_2d"}}) {
    if (value == 0 || value < -1)
      return Fail(std::string(name) + " must be >= 1 (or -1 for the preset's)");
  }
  if (!(FLAGS_far_radius > 1 && FLAGS_far_radius <= 1e4))
    return Fail("--far_radius must be in (1, 10000] scene extents");
  if (FLAGS_warmup_max_iterations >= 0) options.warmup_max_iterations = FLAGS_warmup_max_iterations;
  if (FLAGS_warmup_min_iterations >= 0) options.warmup_min_iterations = FLAGS_warmup_min_iterations;
  if (FLAGS_mutual_iterations >= 0) options.mutual_iterations = FLAGS_mutual_iterations;
  ro.geometry_hold_from_scene = FLAGS_mutual_iterations_2d == -2;
  if (FLAGS_mutual_iterations_2d != -2) options.mutual_iterations_2d = FLAGS_mutual_iterations_2d;
  if (FLAGS_position_lr_max_steps > 0) options.position_lr_max_steps = FLAGS_position_lr_max_steps;
  if (FLAGS_position_lr_max_steps_2d > 0)
    options.position_lr_max_steps_2d = FLAGS_position_lr_max_steps_2d;
  options.surfel_shape_decay = FLAGS_surfel_shape_decay;
  if (!mgsr::SolverOptions::ApplyMethod(FLAGS_method, &options))
    return Fail("unknown --method '" + FLAGS_method + "' (mgsr, 2dgs, 3dgs or 3dgs-ref)");
  options.auto_stop = FLAGS_auto_stop;
  options.bidirectional = FLAGS_bidirectional;
  options.density = FLAGS_density;
  if (!FLAGS_density_config.empty()) {
    options.density_config = nlohmann::json::parse(FLAGS_density_config, nullptr, false);
    if (options.density_config.is_discarded())
      return Fail("--density_config is not valid JSON: " + FLAGS_density_config);
  }
  ro.budget = FLAGS_budget;
  options.prune_contribution = FLAGS_prune_contribution;
  ro.max_gaussians = FLAGS_max_gaussians;
  ro.max_surfels = FLAGS_max_surfels;
  options.w_2d = FLAGS_w_2d;
  options.w_3d = FLAGS_w_3d;
  options.w_depth = FLAGS_w_depth;
  options.lambda_l1 = FLAGS_lambda_l1;
  ro.normal_weight_from_scene = FLAGS_lambda_normal == -1;
  if (FLAGS_lambda_normal >= 0) {
    options.lambda_normal = FLAGS_lambda_normal;
  } else if (FLAGS_lambda_normal != -1) {
    return Fail("--lambda_normal must be >= 0 (or -1 for the default)");
  }
  ro.mask_from_scene = FLAGS_lambda_mask == -1;
  ro.distortion_from_scene = FLAGS_lambda_distortion == -1;
  ro.surfel_layer_from_spread = FLAGS_lambda_surfel_layer == -1;
  ro.one_sided_from_scene = gflags::GetCommandLineFlagInfoOrDie("normal_one_sided").is_default;
  ro.depth_tv_from_scene = FLAGS_depth_tv_warmup_2d == -1 && FLAGS_depth_tv_mutual_2d == -1;
  // Weights whose -1 means "the default" (some chosen from the scene by the pipeline).
  for (auto [flag, value, name] :
       {std::tuple{FLAGS_depth_tv_warmup_2d, &options.depth_tv_warmup_2d, "--depth_tv_warmup_2d"},
        std::tuple{FLAGS_depth_tv_mutual_2d, &options.depth_tv_mutual_2d, "--depth_tv_mutual_2d"},
        std::tuple{FLAGS_lambda_distortion, &options.lambda_distortion, "--lambda_distortion"},
        std::tuple{FLAGS_lambda_mask, &options.lambda_mask, "--lambda_mask"},
        std::tuple{FLAGS_lambda_mask_warmup, &options.lambda_mask_warmup, "--lambda_mask_warmup"},
        std::tuple{FLAGS_lambda_multiview_ncc, &options.lambda_multiview_ncc,
                   "--lambda_multiview_ncc"},
        std::tuple{FLAGS_lambda_multiview_depth, &options.lambda_multiview_depth,
                   "--lambda_multiview_depth"},
        std::tuple{FLAGS_lambda_surfel_layer, &options.lambda_surfel_layer,
                   "--lambda_surfel_layer"},
        std::tuple{FLAGS_normal_edge_weight, &options.normal_edge_weight, "--normal_edge_weight"},
        std::tuple{FLAGS_normal_robust_scale, &options.normal_robust_scale,
                   "--normal_robust_scale"},
        std::tuple{FLAGS_normal_agreement_floor, &options.normal_agreement_floor,
                   "--normal_agreement_floor"}}) {
    if (flag >= 0) {
      *value = flag;
    } else if (flag != -1) {
      return Fail(std::string(name) + " must be >= 0 (or -1 for the default)");
    }
  }
  options.tv_on_geometry = FLAGS_tv_on_geometry;
  options.normal_one_sided = FLAGS_normal_one_sided;
  ro.depth_tv_disparity = FLAGS_depth_tv_disparity;
  options.multiview_neighbours = FLAGS_multiview_neighbours;
  options.normal_depth_gradient = FLAGS_normal_depth_gradient;
  if (!(FLAGS_lambda_normal_mutual >= 0 || FLAGS_lambda_normal_mutual == -1))
    return Fail("--lambda_normal_mutual must be >= 0 (or -1 for --lambda_normal's)");
  options.lambda_normal_mutual = FLAGS_lambda_normal_mutual;
  options.lambda_normal_tv = FLAGS_lambda_normal_tv;
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
  if (FLAGS_mesh_depth != "expected" && FLAGS_mesh_depth != "median")
    return Fail("--mesh_depth must be expected or median");
  if (FLAGS_mesh_color != "transmitted" && FLAGS_mesh_color != "surfel")
    return Fail("--mesh_color must be transmitted or surfel");
  ro.surface.resolution_scale = FLAGS_mesh_resolution_scale;
  ro.surface.median_depth = FLAGS_mesh_depth == "median";
  if (mgsr::Status e = mgsr::ParseExportFormats(FLAGS_export, &ro.export_formats); !e.ok())
    return Fail(e.message());
  ro.surface.surfel_color = FLAGS_mesh_color == "surfel";
  ro.surface.voxel_size = FLAGS_voxel_size;
  ro.surface.truncation_voxels = FLAGS_tsdf_truncation;
  ro.mesh_region = FLAGS_mesh_region;
  ro.surface.free_space = FLAGS_mesh_free_space;
  ro.checkpoint_every = FLAGS_checkpoint_every;
  ro.log_every = FLAGS_log_every;
  ro.eval_every = FLAGS_eval_every;
  ro.profile = FLAGS_profile;
  ro.background = FLAGS_background;
  ro.scene.downscale = FLAGS_downscale;
  ro.scene.max_width = FLAGS_max_width;
  ro.scene.max_size = FLAGS_max_size;
  ro.scene.test_every = FLAGS_test_every;
  ro.scene.seed = FLAGS_seed;
  ro.scene.far_points = FLAGS_far_points;
  ro.scene.far_radius = FLAGS_far_radius;
  ro.colmap = mgsr_tools::ColmapOptionsFromFlags();
  ro.on_colmap_summary = mgsr_tools::PrintColmapSummary;
  ro.preset = FLAGS_preset;
  ro.method = FLAGS_method;
  ro.surfel_low_pass = FLAGS_surfel_low_pass;
  ro.surfel_init = FLAGS_surfel_init;
  if (!FLAGS_loss_config.empty()) {
    // Here for the listing and to refuse a bad file before the scene is read; the pipeline
    // applies it again once the scene has chosen its weights.
    options.losses = options.LossTable();
    const mgsr::Status l = mgsr::ApplyLossConfigFile(FLAGS_loss_config, &options.losses);
    if (!l.ok()) return Fail(l.message());
    ro.loss_config = FLAGS_loss_config;
  }
  if (listing) {
    // The budgets come from the scene, which a listing does not read: stand-ins for them.
    mgsr::SolverOptions shown = options;
    shown.max_gaussians = shown.max_surfels = 1;
    const mgsr::Status valid = shown.Validate();
    if (!valid.ok()) return Fail(valid.message());
    PrintLosses(options);
    return 0;
  }
  options.batch_views = FLAGS_batch_views;
  options.batch_sqrt_lr = FLAGS_batch_sqrt_lr;
  options.coarse_fraction = FLAGS_coarse_fraction;
  options.coarse_levels = FLAGS_coarse_levels;
  ro.coarse_max_size = FLAGS_coarse_max_size;
  ro.batch_scale_iterations = !FLAGS_batch_keep_iterations;
  ro.group = group;
  const mgsr::Status valid = ro.Validate();
  if (!valid.ok()) return Fail(valid.message());

  mgsr::ReconstructionPipeline pipeline(ro);
  g_pipeline = &pipeline;
  std::signal(SIGINT, OnSigint);
  mgsr::ReconstructionEnd end = mgsr::ReconstructionEnd::kFinished;
  const mgsr::Status s = pipeline.Run(&end);
  // The handler stays (it does nothing without a pipeline): a Ctrl-C after the outputs are
  // complete must not turn a finished run into a killed one (exit 130) while the process exits.
  g_pipeline = nullptr;
  if (!s.ok()) return Fail(s.message());
  return end == mgsr::ReconstructionEnd::kInterrupted ? 130 : 0;
}

int main(int argc, char** argv) {
  mgsr_tools::PreferShortOpenMpSpins(argv);
  std::unique_ptr<mgsr::ViewGroup> group;
#ifdef MGSR_WITH_MPI
  // Under mpirun: one process of the job (the others run the same command); process 0 prints and
  // writes, the others train alongside it silently.
  mgsr::MpiViewGroup* mpi = nullptr;
  if (mgsr::MpiViewGroup::Launched()) {
    std::unique_ptr<mgsr::MpiViewGroup> g = mgsr::MpiViewGroup::Init(&argc, &argv);
    mpi = g.get();
    group = std::move(g);
    if (group->rank() != 0) {
      if (std::freopen("/dev/null", "w", stdout) == nullptr) return 1;
      g_error_prefix = "MPI process " + std::to_string(group->rank()) + ": ";
    }
  }
#else
  // Several copies started by mpirun would each train alone and write the same folder.
  if (mgsr::LaunchedProcesses() > 1) {
    std::fprintf(stderr,
                 "error: started as one of %d MPI processes, but this mgsr_solve was built "
                 "without MPI: rebuild with -DMGSR_WITH_MPI=ON (scripts/build.sh does)\n",
                 mgsr::LaunchedProcesses());
    return 1;
  }
#endif
  const int code = Main(argc, argv, group.get());
#ifdef MGSR_WITH_MPI
  // A process that fails or stops alone ends the job (the others may be waiting for it in a
  // collective); what process 0 checkpointed stays.
  if (code != 0 && mpi != nullptr && mpi->size() > 1) mpi->Abort(code);
#endif
  return code;
}
