// The mesh of a trained solver (method.md 5; docs/design.md): the geometry branch's depth for
// every training view, rendered at `resolution_scale` times the training resolution (the models
// are continuous, so a finer depth map is a better sample of the same surface) and fused into a
// TSDF whose voxel matches the finer pixel footprint. Also the exact-depth ceiling of the same
// cameras and settings, and signed depth diagnostics against a ground-truth mesh.
#pragma once

#include <Eigen/Geometry>
#include <functional>
#include <string>

#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"
#include "mgsr/eval/depth_error.h"
#include "mgsr/eval/normal_error.h"
#include "mgsr/io/scene.h"
#include "mgsr/mesh/exact_depth_ceiling.h"
#include "mgsr/mesh/tsdf_fusion.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/solver_options.h"

namespace mgsr {

struct SurfaceOptions {
  int resolution_scale = 1;      // render depth for fusion at this many times the resolution
  bool median_depth = false;     // fuse the 2DGS median depth instead of the expected depth
  bool surfel_color = false;     // colour the mesh by the 2DGS render (default: 3DGS transmitted)
  double voxel_size = 0;         // 0: the pixel footprint at the object / resolution_scale
  double truncation_voxels = 4;  // at resolution_scale 1; kept in scene units at finer scales
  bool keep_largest_component = true;
  // Remove what more views see through than hold (mgsr/mesh/seen_through.h).
  bool free_space = true;
  // What is meshed (fusion_region.h): empty for everything the depth reaches. With it, the
  // clean-up keeps components of at least min_component_share of the largest (see TsdfOptions).
  Eigen::AlignedBox3d region;
  double min_component_share = 1.0;
};

// Sets options->region and the clean-up from `spec`: "auto" (RegionFromCameras over the training
// cameras), "none", or a box / region file (ParseRegion). Without masks, components of at least 2%
// of the largest stay (a scene's object need not touch its ground); with masks the largest alone,
// as ever. `note` says what was chosen, for the log and metrics.json.
Status ResolveMeshRegion(const std::string& spec, const Scene& scene, SurfaceOptions* options,
                         std::string* note);

// The scene units one training pixel covers at the object (median over the training cameras,
// at the point their optical axes meet).
double TrainingFootprint(const Scene& scene);

// The fusion settings for `scene`: the voxel resolved (footprint / scale unless given) and the
// truncation band kept at truncation_voxels training footprints.
TsdfOptions SurfaceTsdfOptions(const Scene& scene, const SurfaceOptions& options);

// The median distance of the training cameras from the point their optical axes meet.
double ObjectDistance(const Scene& scene);

// The training cameras (in TrainIndices order), and the same at the fusion resolution.
std::vector<Camera> TrainingCameras(const Scene& scene);
std::vector<Camera> FusionCameras(const Scene& scene, int resolution_scale);

// Renders and fuses the trained geometry of every training view; depth is kept where the render's
// alpha times the view's mask (if any) is at least 0.5. `progress`, when given, is called after
// each view with (views fused, views in all). With a `group` of several processes (all holding
// the same trained models, all calling this) the views are rendered round robin and process 0
// fuses them in order, so its mesh is the one a single process makes; the others return no mesh.
// `free_space`, when given, receives what the free-space test removed.
Status ExtractSurface(MutualBoostedSolver* solver, const SolverOptions& solver_options,
                      const Scene& scene, const SurfaceOptions& options, TriangleMesh* mesh,
                      const std::function<void(int, int)>& progress = {},
                      ViewGroup* group = nullptr, SeenThroughStats* free_space = nullptr);

// The same fusion of the ground truth's exact depth: what this fusion can achieve at best.
// `training_depth` holds the ground truth's exact depth for TrainingCameras(scene); at a finer
// fusion resolution its caster casts the finer views.
Status ExactDepthCeiling(ExactDepthViews* training_depth, const Scene& scene,
                         const SurfaceOptions& options, TriangleMesh* mesh);

// Signed depth error of the geometry branch's expected and median depth on the training views
// (inside the masks), against the ground truth's exact depth for TrainingCameras(scene).
// Also the angle between the rendered 2DGS normals and the true surface normals.
struct SurfaceDepthReport {
  DepthErrorStats expected, median;
  NormalErrorStats normal;
};
SurfaceDepthReport MeasureSurfaceDepth(MutualBoostedSolver* solver,
                                       const SolverOptions& solver_options, const Scene& scene,
                                       ExactDepthViews* training_depth);

}  // namespace mgsr
