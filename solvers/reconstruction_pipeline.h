// The whole job, from a workspace (or photos) to a reconstruction folder, like COLMAP's automatic
// reconstruction controller: colmap when given photos, loading the scene, choosing the backgrounds
// and budgets, training (checkpoints, resume, Ctrl-C), the test views' scores and renders, the
// models, the TSDF mesh, and metrics.json with the exact geometry figures when the scene has a
// ground truth. mgsr_solve maps its flags onto ReconstructionOptions and runs it.
#pragma once

#include <csignal>
#include <cstdint>
#include <functional>
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "mgsr/core/status.h"
#include "mgsr/io/scene.h"
#include "mgsr/sfm/colmap_pipeline.h"
#include "solvers/solver_options.h"
#include "solvers/surface_extraction.h"

namespace mgsr {

class MutualBoostedSolver;
struct SolveSummary;
class ViewGroup;

struct ReconstructionOptions {
  // Input: a workspace (COLMAP, Blender/NeRF or mgsr_synth), or photos (and optional masks) that
  // colmap turns into one inside the output folder first (`colmap` holds its settings).
  std::string workspace, images, masks;
  ColmapPipelineOptions colmap;
  // Called with colmap's summary when it ran (mgsr_solve prints it).
  std::function<void(const ColmapPipelineSummary&)> on_colmap_summary;
  SceneOptions scene;
  // "auto" (the photos' uniform backdrop when there is one, else the reference's), "reference"
  // (2DGS white, 3DGS black) or a grey level in [0, 1] for both branches.
  std::string background = "auto";

  // Output and run control.
  std::string output;
  bool overwrite = false;   // replace an earlier run's results (else the folder must be new)
  bool resume = false;      // continue from output/checkpoints/latest.ckpt
  bool check_only = false;  // load the scene (and the checkpoint) and stop; writes nothing
  int checkpoint_every = 500;
  int log_every = 100;   // a progress line every N iterations
  int eval_every = 500;  // a test-view PSNR line every N iterations (0: none)
  // Time every stage of an iteration (projection, binning, raster, losses, Adam, ...) and print
  // ms per iteration per stage and branch at the end of training (also in metrics.json "profile").
  bool profile = false;

  // Training. The primitive budget of each branch: max_gaussians / max_surfels when >= 0 (0 is
  // none), else from `budget`: "auto" (AutoPrimitiveBudget: from the foreground the views show),
  // "scene" (DefaultPrimitiveBudget: a safety bound far above need), "none", or a count for both;
  // empty is the density strategy's own default (mcmc: auto; reference: scene).
  SolverOptions solver;
  // Sets solver.lambda_normal from the scene: kNormalWeightWithForeground (2.0) where every
  // training view has a mask or alpha, the reference's 0.05 where none tells the object from its
  // backdrop. Without masks, grey surfels on a uniform backdrop cost the photometric loss nothing,
  // and a strong normal term then grows them into a sheet in front of the object (harness
  // no_masks scene: NC 65.6 at 2.0, 94.3 at 0.05). Off: solver.lambda_normal as given.
  bool normal_weight_from_scene = false;
  // Where every training view has a mask or alpha: the silhouette term at kMaskWeightWithForeground
  // (solver.lambda_mask; mask_from_scene) and one-sided differences at depth steps in the normal
  // consistency (solver.normal_one_sided; one_sided_from_scene). The masks say where every view
  // agrees there is no object: without the term holes and gaps web over (docs/geometry.md,
  // "Silhouettes"). Without masks both stay as given (the term has nothing to read, and one-sided
  // differences alone raised CD on the scene-level captures).
  bool mask_from_scene = false;
  bool one_sided_from_scene = false;
  // Sets solver.lambda_distortion from the scene: kDistortionWeightWithoutForeground (1000, 2DGS's
  // weight for its object scenes) where no mask or alpha tells the object from its backdrop, the
  // reference's 0 where they do. Without masks nothing else keeps surfels in one layer: over a
  // long mutual stage a second layer, each view seeing its own, fits each photo's light (harness
  // indoor_mirror, `paper`: CD x1000 28.97 -> 19.47; docs/geometry.md, "Training longer"). With
  // masks the silhouette does that, and the term moved CD both ways (mirror up, the slot down).
  // Off: solver.lambda_distortion as given.
  bool distortion_from_scene = false;
  // Where every training view has a mask or alpha and the mutual stage is longer than `fast`'s:
  // SolverOptions::HoldGeometryAtFast (both branches on `fast`'s schedules; the 2DGS branch trains
  // for `fast`'s mutual iterations, then is held while the 3DGS branch trains on). Under the strong
  // normal prior of such scenes the longer stage fills concavities (docs/geometry.md, "Training
  // longer"). Without masks the whole stage trains both: there the long stage with the depth
  // distortion lowers CD. Off: solver.mutual_iterations_2d as given.
  bool geometry_hold_from_scene = false;
  // Sets the depth TVs (both branches') from the scene: off where the background is learnt (a
  // scene in the world: no masks, photos whose borders vary), the reference's weights (solver's
  // depth_tv_* as given) otherwise. In a scene-level capture every silhouette, horizon and
  // receding ground and wall is a depth step a TV pulls on in scene units; from the first
  // iterations, where the 2DGS one outweighs the photometric loss, it draws the ground and walls
  // towards the cameras. MGSR NC, both TVs on -> 2DGS ones off -> all off: harness outdoor 75.4
  // -> 88.0 -> 89.8, indoor_mirror 84.3 -> 90.1 -> 89.6, fresh outdoor / indoor captures 80.8 ->
  // 87.7 -> 88.7 and 79.9 -> 86.1 -> 85.9. On an object before a uniform backdrop (no masks) the
  // 2DGS one is needed: off there, the harness's no_masks scene drops from NC 93.8 to 80.3.
  bool depth_tv_from_scene = false;
  // Where every training view has a mask or alpha: solver.spread_initial_surfels (mgsr_solve
  // --surfel_spread masked, its default). Without masks nothing holds a backdrop's small first
  // disks in one layer and the mesh loses NC, so without them the disks stay one per point
  // (docs/geometry.md, "How large the first disks are", "The spread by default"). Off:
  // solver.spread_initial_surfels as given.
  bool spread_from_scene = false;
  // solver.lambda_surfel_layer = SolverOptions::kSurfelLayerWeightWithSpread where the initial
  // disks are spread (solver.spread_initial_surfels, as given or chosen above), else 0 (mgsr_solve
  // --lambda_surfel_layer -1): the prior thins the layer the small first disks form on a slot's
  // walls, and costs NC where the first disks are wide (docs/geometry.md, "A layer of disks").
  bool surfel_layer_from_spread = false;
  // A JSON file of loss-table edits (ApplyLossConfigFile), applied to solver's table once the
  // weights chosen from the scene (above) are set, so its rows change those, not the defaults.
  std::string loss_config;
  // The depth TVs on the disparity s^2 / D, s = ObjectDistance(scene) (SolverOptions::
  // tv_disparity_scale).
  bool depth_tv_disparity = false;
  std::string budget;
  int64_t max_gaussians = -1, max_surfels = -1;
  // The coarse start (SolverOptions::coarse_factor): training views longer than this many px
  // train the first part of each stage (solver.coarse_fraction) divided by the smallest integer
  // that brings them within it. 0: always at full size.
  int coarse_max_size = 800;

  // The mesh. `mesh_region` resolves surface.region once the scene is read (ResolveMeshRegion):
  // "auto", "none", a box "x0,y0,z0,x1,y1,z1" or a region file.
  SurfaceOptions surface;
  std::string mesh_region = "auto";
  // Formats of the 3DGS model: "ply" (point_cloud_3d.ply, with the reflection attributes),
  // "splat", "spz" (splat_formats.h); ParseExportFormats checks the list.
  std::vector<std::string> export_formats = {"ply"};

  // The processes that share each batch of views (solver.batch_views; an MPI job's, from
  // mgsr_solve under mpirun), or null for this process alone. Process 0 writes everything (log,
  // checkpoints, models, renders, mesh, metrics); the others load the same scene and checkpoint,
  // train the same models alongside it, render their share of the mesh's depth frames for it
  // (ExtractSurface) and write nothing. Photos (`images`) are refused: run the
  // photo pipeline once, then the job on its workspace.
  ViewGroup* group = nullptr;
  // With solver.batch_views > 1: divide the solver's iteration counts by it once the scene's
  // choices and the loss config are applied (SolverOptions::ScaleIterationsForBatch), so the run
  // sees as many views as one view per step would.
  bool batch_scale_iterations = false;
  // How `solver` was chosen, recorded in metrics.json.
  std::string preset = "fast", method = "mgsr", surfel_low_pass = "area",
              surfel_init = "neighbours";

  // Which input and output: one of workspace and images, masks only with images, an output unless
  // only checking, not both resume and overwrite. Errors name the option as the command line
  // spells it.
  Status CheckInputsAndOutput() const;
  // That, and every value (the solver's options included).
  Status Validate() const;
};

// "background" as ReconstructionOptions takes it: -1 in `level` for auto or reference.
Status ParseBackground(const std::string& background, double* level);

enum class ReconstructionEnd {
  kFinished,     // every output written
  kChecked,      // check_only: the scene (and checkpoint) can be trained
  kInterrupted,  // RequestStop: the state is checkpointed, --resume continues
};

class ReconstructionPipeline {
 public:
  explicit ReconstructionPipeline(ReconstructionOptions options) : options_(std::move(options)) {}
  // Runs the job. On an error (one line naming the file or option and the problem) the results
  // this run wrote are taken back; a trained state stays in the checkpoint.
  Status Run(ReconstructionEnd* end);
  // Safe from a signal handler: training stops at the iteration's end and is checkpointed; while
  // the outputs are written, the ones written so far are taken back and the trained state kept.
  void RequestStop();

 private:
  // The state one run hands from stage to stage (defined beside Run).
  struct RunState;
  // The stages, in order; Run calls them one after the other until one fails or ends the run
  // early (sets RunState::stopped: --check, Ctrl-C, a process that only trains alongside).
  Status RunStages(RunState* st);
  Status OpenOutput(RunState* st);           // checks the options, locks the output folder
  Status RunColmap(RunState* st);            // photos given: colmap makes the workspace
  Status LoadInput(RunState* st);            // reads the scene and checks it can be trained
  Status ChooseSceneSettings(RunState* st);  // backgrounds, weights, the loss configuration
  Status ChooseBudget(RunState* st);         // the primitive budget of each branch
  Status ChooseCoarseLevel(RunState* st);    // the size the first part of each stage trains at
  Status ChooseMeshRegion(RunState* st);     // the region the mesh is fused in
  Status ChooseBatches(RunState* st);        // views per step; checks the final options
  Status CreateSolver(RunState* st);         // the models; a group's agreement; --resume
  Status FollowOrCheck(RunState* st);        // other processes of a group; --check ends here
  Status PrepareOutputs(RunState* st);       // clears the old results; log and callbacks
  Status TrainModels(RunState* st);          // training; the finished state checkpointed
  Status WriteModels(RunState* st);          // the branches' models and learnt backgrounds
  Status ScoreTestViews(RunState* st);       // test-view scores and renders
  Status ExtractMesh(RunState* st);          // TSDF fusion of the 2DGS depth: mesh.ply
  Status WriteMetrics(RunState* st);         // metrics.json (the run's manifest) and summary
  // One test view's scores (added to st->test) and renders.
  Status ScoreTestView(RunState* st, const View& view);
  // metrics.json's content but for the ground-truth geometry and the manifest.
  nlohmann::json MetricsJson(const RunState& st) const;
  // Ctrl-C while writing the outputs: takes back the results so far, keeps the trained state.
  Status StopWriting(RunState* st);

  // Solve with profiling as asked, RequestStop reaching the solver while it trains.
  Status Train(MutualBoostedSolver* solver, SolveSummary* summary);
  // A process of a group other than process 0: trains alongside it, renders its share of the
  // mesh's depth frames for it, and writes nothing.
  Status TrainAlongside(MutualBoostedSolver* solver, const SolverOptions& options,
                        const Scene& scene, const SurfaceOptions& surface, ReconstructionEnd* end);
  ReconstructionOptions options_;
  MutualBoostedSolver* volatile solver_ = nullptr;  // while training
  volatile std::sig_atomic_t stop_requested_ = 0;
};

}  // namespace mgsr
