// SolverOptions: every schedule, weight and rate of MGSR's optimisation, with the reference
// defaults (docs/method.md 1.1-1.13), and presets that scale them. A plain struct with a
// validating check, like ceres::Solver::Options.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "mgsr/core/status.h"
#include "mgsr/loss/exposure_compensation.h"
#include "solvers/loss_table.h"

namespace mgsr {

struct BranchSchedule {
  int densify_from = 500, densify_until = 15000, densify_interval = 100;
  int opacity_reset_interval = 3000;  // resets while densifying
  float min_opacity = 0.05f;          // prune threshold
  bool operator==(const BranchSchedule& o) const {
    return densify_from == o.densify_from && densify_until == o.densify_until &&
           densify_interval == o.densify_interval &&
           opacity_reset_interval == o.opacity_reset_interval && min_opacity == o.min_opacity;
  }
};

// The 2DGS normal-consistency weight: the reference's, and this project's default for objects
// whose pixels are known (masks or alpha; docs/geometry.md, state D).
constexpr double kReferenceNormalWeight = 0.05;
constexpr double kNormalWeightWithForeground = 2.0;
// The 2DGS depth distortion where no mask tells the object from its backdrop (2DGS's weight for
// its object scenes; ReconstructionOptions::distortion_from_scene).
constexpr double kDistortionWeightWithoutForeground = 1000.0;
// The silhouette term's weight where the views have masks or alpha (docs/geometry.md).
constexpr double kMaskWeightWithForeground = 3.0;

struct SolverOptions {
  // Warm-up: each branch steps until its loss window flattens (after a minimum iteration) or a cap.
  bool auto_stop = true;
  int warmup_min_iterations = 15000;
  int warmup_max_iterations = 20000;
  int auto_stop_window = 100;
  double auto_stop_range = 0.01;
  // Mutual stage.
  int mutual_iterations = 20000;
  // The 2DGS branch (the geometry) steps in the first `mutual_iterations_2d` mutual iterations
  // only (-1: in all of them). After them it is held: it renders the depth that supervises the
  // 3DGS branch, which trains on to the end of the stage. HoldGeometryAtFast sets it.
  int mutual_iterations_2d = -1;
  std::string mutual_mode = "alternate";  // alternate | joint
  // Ablation K: the supervising branch also receives the gradient of the supervision (through the
  // 3DGS transmitted image for the 2DGS render loss, through the 2DGS depth for the depth loss) and
  // steps with it. The TV guides stay constant.
  bool bidirectional = false;
  // Which parts train (the harness's methods): a single branch skips the mutual stage; without
  // reflection the 3DGS branch is plain 3DGS (reflected opacity ~0 and frozen, so C = C_tran).
  bool train_2d = true, train_3d = true;
  bool reflection = true;
  // Loss weights (method.md 1.3-1.7).
  double lambda_l1 = 0.8;  // render loss: lambda L1 + (1 - lambda) D-SSIM
  // Normal consistency. The reference uses 0.05; at that weight the trained disks
  // stay tilted (4-20 degrees off the true normal, larger disks more), each tilted disk's near rim
  // stands out of the surface unless its centre sits deeper, and the surface ends 0.4-1.0 px
  // inside the truth. 2.0 aligns them: 0.1-0.25 px on five scenes, CD 2-4x lower, NC up (docs/
  // geometry.md). 4.0 over-smooths concavities.
  double lambda_normal = kNormalWeightWithForeground;
  int normal_from_iteration = 7000;  // warm-up: normal terms off before this
  // >= 0: the normal consistency's weight in the mutual stage (before w_2d); -1: lambda_normal.
  double lambda_normal_mutual = -1;
  // The edge-aware TV of the rendered normals: the reference's weight (its lambda_4 = 1 times its
  // normal weight 0.05), whatever lambda_normal is. It acts where neighbouring normals differ,
  // which on a smooth surface is little and at a crease is everything: tied to lambda_normal at
  // 2.0 it rounded every edge of the detailed shapes (docs/geometry.md, "The normal TV, and the
  // patch term by default").
  double lambda_normal_tv = 0.05;
  // false: the normal consistency does not pull the depth (only the rendered normals turn).
  bool normal_depth_gradient = true;
  // > 0: the normal consistency relaxes where the photo has edges (NormalConsistencyLoss).
  double normal_edge_weight = 0;
  // > 0: the normal consistency's residual is bounded (NormalConsistencyLoss robust_scale).
  double normal_robust_scale = 0;
  // true: the normal consistency's depth normal from one-sided differences (NormalConsistencyLoss).
  bool normal_one_sided = false;
  // < 1: the normal consistency falls towards this fraction where the neighbouring photos agree
  // with the rendered plane (NormalConsistencyLoss agreement_floor); 1: off.
  double normal_agreement_floor = 1;
  // 2DGS depth distortion (method.md 3.4). MGSR leaves it at 0; 2DGS uses 1000 from 3000 on.
  double lambda_distortion = 0.0;
  int distortion_from_iteration = 3000;
  // Multi-view consistency of the 2DGS branch (docs/geometry.md): the patch NCC through the
  // rendered plane and the forward-backward depth reprojection, against `multiview_neighbours`
  // neighbouring views each (chosen once from the points' co-visibility). Warm-up: from
  // multiview_from_iteration; mutual stage: throughout, times w_2d.
  // Silhouette: the 2DGS alpha against the foreground mask (MaskLoss), warm-up and mutual stage
  // (times w_2d); 0 without masks whatever the weight. lambda_mask_warmup >= 0 gives the warm-up
  // its own weight (-1: lambda_mask in both stages).
  double lambda_mask = 0.0;
  double lambda_mask_warmup = -1.0;
  double MaskWarmupWeight() const {
    return lambda_mask_warmup >= 0 ? lambda_mask_warmup : lambda_mask;
  }
  // The patch term is on by default (0.15): with its outlier test it lowered CD on the scene-level
  // captures by a third to a half, on the detailed shapes and on most objects, and cost the
  // twelve-view scene 0.3 NC (docs/geometry.md, "The normal TV, and the patch term by default").
  // The depth term stays off: it pulls a groove towards the tooth a neighbour sees in front of it.
  double lambda_multiview_ncc = 0.15;
  double lambda_multiview_depth = 0.0;
  // The surfel layer prior's weight (solvers/surfel_layer_prior.h), per view, both stages; 0: no
  // rows. It thins the layer of disks a slot's walls form, with the spread first disks; without
  // them, and on printed planes, it costs NC (docs/geometry.md, "A layer of disks"), so it is off
  // here. kSurfelLayerWeightWithSpread: the weight mgsr_solve gives it where the initial disks
  // are spread (--lambda_surfel_layer -1), which with masks is its default.
  double lambda_surfel_layer = 0.0;
  static constexpr double kSurfelLayerWeightWithSpread = 10.0;
  int multiview_from_iteration = 7000;
  int multiview_neighbours = 2;
  double depth_tv_warmup_2d = 1.0;
  double depth_tv_mutual_2d = 0.05;
  double transmitted_tv_3d = 0.1;
  double depth_tv_3d = 0.05;
  // The depth and normal TVs only between pixels the branch covers (EdgeAwareTvLoss on_geometry).
  bool tv_on_geometry = false;
  // > 0: the depth TVs on s^2 / D (EdgeAwareTvLoss disparity_scale), s the object's distance.
  double tv_disparity_scale = 0;
  double w_2d = 0.5, w_3d = 0.5, w_depth = 0.01;
  double mutual_transmitted_weight = 0.2, mutual_image_weight = 0.8;
  // The loss table (solvers/loss_table.h). Empty: the paper's, built from the weights above when
  // the solver starts (so presets and the weight flags apply); otherwise exactly these rows.
  std::vector<LossSpec> losses;
  std::vector<LossSpec> LossTable() const {
    return losses.empty() ? PaperLossTable(*this) : losses;
  }
  // Density control.
  BranchSchedule schedule_2d{500, 15000, 100, 3000, 0.05f};
  BranchSchedule schedule_3d{50, 2500, 20, 500, 0.005f};
  float densify_grad_threshold = 2e-4f;
  float percent_dense = 0.01f;
  size_t max_gaussians = 0, max_surfels = 0;  // 0 = no budget
  // The density strategy of both branches (DensityStrategyRegistry: "reference", "mcmc", ...) and
  // its config (null: the strategy's defaults). "mcmc" needs a budget in each branch it trains,
  // so the library's default stays "reference"; mgsr_solve defaults to "mcmc" with a budget from
  // the scene (ReconstructionPipeline, AutoPrimitiveBudget).
  std::string density = "reference";
  nlohmann::json density_config;
  // Pruning by contribution at the end of each stage: a primitive whose blend weights, summed
  // over every pixel of every training view, stay below this is dropped (0: off), so the saved
  // models hold only what renders.
  double prune_contribution = 0;
  // Learning rates (method.md 1.8); positions scale with the scene extent and decay log-linearly
  // over position_lr_max_steps iterations of each stage (the reference's 30,000), the 2DGS
  // branch's over position_lr_max_steps_2d when that is >= 1 (-1: the same). Both presets
  // decay the 2DGS rate over 2,250 (FromPreset).
  double position_lr_init = 1.6e-4, position_lr_final = 1.6e-6;
  int position_lr_max_steps = 30000;
  int position_lr_max_steps_2d = -1;
  int PositionDecaySteps(Branch branch) const {
    return branch == Branch::kSurfels2D && position_lr_max_steps_2d >= 1 ? position_lr_max_steps_2d
                                                                         : position_lr_max_steps;
  }
  double feature_lr = 2.5e-3, opacity_lr = 0.05, scaling_lr = 5e-3, rotation_lr = 1e-3;
  // In a stage longer than the 2DGS branch's position decay, let the surfels' shape settle after
  // their position has: from step PositionDecaySteps(2D) on, the 2DGS scale and rotation rates
  // fall log-linearly by position_lr_final / position_lr_init over as many steps again. A stage
  // that ends before that (`fast`'s) is unchanged. Off by default: in `paper`'s 20,000 mutual
  // iterations it keeps a room's floor from bending to each view's light (indoor_mirror), but
  // costs detailed shapes their grooves (the gear); docs/geometry.md, "Training longer".
  bool surfel_shape_decay = false;
  // SH degree grows by one every `sh_interval` warm-up iterations up to `sh_degree`.
  int sh_degree = 3, sh_interval = 1000;
  // Grey level each branch renders on and composites its masked photos on: 2DGS white, 3DGS black
  // (method.md 1.12, OmniObject3D setting). Photos without masks keep their own backdrop, so for
  // them both are set to the backdrop's level (solvers/backdrop.h) and empty space needs no
  // primitives.
  float background_2d = 1.0f, background_3d = 0.0f;
  // Instead: each branch learns a background per viewing direction
  // (solvers/environment_background.h) for what no primitive covers, the sky and far background of
  // a scene-level capture.
  bool environment = false;
  // The 2DGS screen low-pass floor (mgsr/render/rasterize_surfels.h): the reference's
  // full-opacity one, or area-preserving (edge-on and sub-pixel surfels do not dilate silhouettes),
  // and its sigma in pixels: the reference's sqrt(2)/2, or by default 0.29, the spread of the
  // pixel's own box. A wide full-opacity floor draws every silhouette about a sigma too far out,
  // and the fit pulls the surface in by as much (docs/geometry.md).
  bool surfel_area_preserving_low_pass = true;
  float surfel_filter_sigma = 0.29f;
  // Initial 2DGS disk orientation: in the plane of each initial point's nearest neighbours
  // (mgsr/model/init_from_points.h), or the reference's random rotation. Small disks get almost no
  // orientation gradient from the photos (the screen low-pass makes them look alike at any tilt),
  // so a random start leaves many tilted, and a tilted disk must sit deeper for its near edge not
  // to stand out of the surface: docs/geometry.md.
  bool surfel_orientation_from_points = true;
  // Spread the initial points over their own surfaces until the 2DGS branch has max_surfels disks
  // (SpreadPointsOverTheirSurfaces; the 3DGS branch keeps one Gaussian per point). A disk starts
  // as wide as the gap to its neighbours, and from a sparse cloud that spans the grooves and slots
  // of a detailed object, which the fit then keeps; smaller first disks recover them. Without
  // masks nothing holds a backdrop's small disks in one layer: docs/geometry.md, "How large the
  // first disks are". Off here (the reference); mgsr_solve turns it on where every view has a
  // mask or alpha (ReconstructionPipelineOptions::spread_from_scene).
  bool spread_initial_surfels = false;
  // Per-view exposure compensation (mgsr/loss/exposure_compensation.h): an affine colour model per
  // training view in front of every comparison with a photo, learned at its own rate with a weak
  // prior towards identity, re-fitted (Huber, solvers/exposure_fit.h) against the warmed-up render
  // when the mutual stage starts. Shared by both branches unless exposure_per_branch.
  // Default affine: measured best on the changing-light scenes (docs/user_guide.md, exposure
  // compensation).
  ExposureMode exposure = ExposureMode::kAffine;
  double exposure_lr = 5e-3;
  double exposure_prior = 1e-3;        // on A - I
  double exposure_offset_prior = 1.0;  // on b: exposure is a gain; offsets only where needed
  double exposure_mean_prior = 10.0;   // on the mean transform over views: fixes the gauge
  bool exposure_per_branch = false;
  bool exposure_fit_at_mutual = true;
  size_t max_init_points = 100000;
  uint64_t seed = 0;
  // Batches of views (--batch_views): each step renders this many training views, sums their
  // gradients (in a fixed order, also when MPI processes share the batch: solvers/view_group.h)
  // and steps once; density statistics sum over the batch. 1: one view per step. With
  // batch_sqrt_lr the parameters' learning rates grow by sqrt(batch_views) (Grendel-GS's rule:
  // fewer, better-informed steps take longer strides).
  int batch_views = 1;
  bool batch_sqrt_lr = true;
  // Coarse start (solvers/view_levels.h): the first `coarse_fraction` of each stage's iterations
  // (of the warm-up cap, of the mutual stage) train on every view divided by `coarse_factor` or
  // more, the rest at full size. The coarse span is split evenly among `coarse_levels` levels,
  // coarsest first, each half the size of the next: factors coarse_factor * 2^(levels - 1), ...,
  // coarse_factor * 2, coarse_factor. 1: none (the pipeline derives it from --coarse_max_size and
  // the photos). The warm-up's auto-stop reads only full-size losses; the mutual stage switches
  // between rounds.
  int coarse_factor = 1;
  double coarse_fraction = 0.75;
  int coarse_levels = 1;
  // The last coarse iteration of each stage (0: none).
  int CoarseWarmupIterations() const;
  int CoarseMutualIterations() const;
  // The last iteration of each coarse level in `stage`, coarsest first: iterations
  // (ends[k - 1], ends[k]] (ends[-1] = 0) train at level coarse_levels - k. Empty without a
  // coarse start.
  std::vector<int> CoarseLevelEnds(Stage stage) const;
  // The last iteration of the k-th coarse span of `stage` (k from 1, coarsest first; k >= the
  // number of levels: the stage's last coarse iteration).
  int CoarseLevelEnd(Stage stage, int k) const;
  // The level `iteration` of `stage` trains at: 0 full size, k >= 1 divided by
  // CoarseLevelFactor(k).
  int CoarseLevelAt(Stage stage, int iteration) const;
  int CoarseLevelFactor(int level) const { return level <= 0 ? 1 : coarse_factor << (level - 1); }
  // Every coarse level's factor, coarsest first (empty without a coarse start).
  std::vector<int> CoarseFactors() const;
  bool CoarseAt(Stage stage, int iteration) const { return CoarseLevelAt(stage, iteration) > 0; }
  // The coarse start as checkpoints record it: "none", "F fraction" (one level) or
  // "F fraction L levels".
  std::string CoarseSetting() const;
  // Divides every iteration count (stage lengths, auto-stop window, density and SH schedules,
  // the position rate's decay, loss rows' first iterations) by `views`, so that a run with
  // batches of that many views sees as many views as a run without.
  void ScaleIterationsForBatch(int views);

  // "paper": the reference's mutual stage (20,000 iterations) and schedules, with fast's warm-up
  // and fast's schedule for what shapes the surface (the 2DGS position rate's decay, the start of
  // the normal and patch terms); "fast": every iteration count scaled to minutes on a laptop CPU.
  static bool FromPreset(const std::string& name, SolverOptions* options);
  // Where the views have masks (ReconstructionOptions::geometry_hold_from_scene): a mutual stage
  // longer than `fast`'s runs `fast` first (the schedules still at `paper`'s values take `fast`'s:
  // both branches' density schedules and position decay, the SH growth, the auto-stop window, the
  // initial points), holds the 2DGS branch after `fast`'s mutual iterations, and trains the 3DGS
  // branch on. Under the strong normal prior of such scenes the longer stage filled concavities,
  // and `paper`'s schedules before that point moved the mesh by about the spread between seeds,
  // on some scenes worse at every seed (docs/geometry.md, "The geometry branch held after
  // `fast`'s mutual stage"). True if it changed anything.
  static bool HoldGeometryAtFast(SolverOptions* options);
  // Sets train_2d / train_3d / reflection for "mgsr", "2dgs" (ablation B), "3dgs" (plain, no
  // reflection) or "3dgs-ref" (ablation A). A single branch gets the warm-up cap plus the mutual
  // iterations as its own cap (auto-stop still applies) and no mutual stage.
  static bool ApplyMethod(const std::string& method, SolverOptions* options);
  Status Validate() const;
  // Every option as (name, value text), in declaration order: what a checkpoint records so that
  // --resume refuses to continue a run under other options, naming the one that differs. A new
  // option adds one line here.
  std::vector<std::pair<std::string, std::string>> Settings() const;
};

}  // namespace mgsr
