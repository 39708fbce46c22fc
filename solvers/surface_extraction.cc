#include "solvers/surface_extraction.h"

#include <algorithm>
#include <cmath>

#include "mgsr/mesh/exact_depth_ceiling.h"
#include "mgsr/mesh/fusion_region.h"
#include "solvers/trained_views.h"
#include "solvers/view_group.h"

namespace mgsr {
namespace {

// A 0/1 mask at the camera's resolution: bilinear over the view's mask (pixel centres at
// half-integers), then thresholded at 0.5, so the silhouette stays smooth at finer scales.
Image ResampleMask(const Image& mask, int width, int height) {
  Image out(width, height, 1, 0.0f);
  const double sx = static_cast<double>(mask.width()) / width;
  const double sy = static_cast<double>(mask.height()) / height;
  for (int y = 0; y < height; ++y) {
    const double fy = std::clamp((y + 0.5) * sy - 0.5, 0.0, mask.height() - 1.0);
    const int y0 = static_cast<int>(fy), y1 = std::min(y0 + 1, mask.height() - 1);
    const double wy = fy - y0;
    for (int x = 0; x < width; ++x) {
      const double fx = std::clamp((x + 0.5) * sx - 0.5, 0.0, mask.width() - 1.0);
      const int x0 = static_cast<int>(fx), x1 = std::min(x0 + 1, mask.width() - 1);
      const double wx = fx - x0;
      const double v = (1 - wy) * ((1 - wx) * mask.at(0, y0, x0) + wx * mask.at(0, y0, x1)) +
                       wy * ((1 - wx) * mask.at(0, y1, x0) + wx * mask.at(0, y1, x1));
      out.at(0, y, x) = v >= 0.5 ? 1.0f : 0.0f;
    }
  }
  return out;
}

}  // namespace

double TrainingFootprint(const Scene& scene) {
  const std::vector<Camera> cameras = TrainingCameras(scene);
  return AutoVoxelSize(cameras, LookAtCenter(cameras));
}

double ObjectDistance(const Scene& scene) {
  const std::vector<Camera> cameras = TrainingCameras(scene);
  const Eigen::Vector3d center = LookAtCenter(cameras);
  std::vector<double> d;
  for (const Camera& c : cameras) d.push_back((c.Center() - center).norm());
  if (d.empty()) return 1.0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}

std::vector<Camera> TrainingCameras(const Scene& scene) {
  std::vector<Camera> cameras;
  for (int i : scene.TrainIndices()) cameras.push_back(scene.views[i].camera);
  return cameras;
}

std::vector<Camera> FusionCameras(const Scene& scene, int resolution_scale) {
  std::vector<Camera> cameras = TrainingCameras(scene);
  for (Camera& c : cameras) c = c.Resized(c.width * resolution_scale, c.height * resolution_scale);
  return cameras;
}

TsdfOptions SurfaceTsdfOptions(const Scene& scene, const SurfaceOptions& options) {
  TsdfOptions t;
  const double footprint = TrainingFootprint(scene);
  const int k = std::max(1, options.resolution_scale);
  t.voxel_size = options.voxel_size > 0 ? options.voxel_size : footprint / k;
  // The band must cover the depth's own error, which does not shrink with the render resolution:
  // keep it in training footprints.
  t.truncation_voxels = options.truncation_voxels * footprint / t.voxel_size;
  t.keep_largest_component = options.keep_largest_component;
  t.free_space = options.free_space;
  t.region = options.region;
  t.min_component_share = options.min_component_share;
  return t;
}

Status ResolveMeshRegion(const std::string& spec, const Scene& scene, SurfaceOptions* options,
                         std::string* note) {
  options->region.setEmpty();
  if (spec == "auto") {
    std::vector<Camera> cameras;
    for (int i : scene.TrainIndices()) cameras.push_back(scene.views[i].camera);
    options->region = RegionFromCameras(cameras);
    *note = options->region.isEmpty()
                ? "auto: the training cameras share no view; everything the depth reaches"
                : "auto (where half the training cameras' frusta meet): " +
                      RegionToString(options->region);
  } else if (spec == "none" || spec.empty()) {
    *note = "none: everything the depth reaches";
  } else {
    const Status s = ParseRegion(spec, &options->region);
    if (!s.ok()) return Status::Error("--mesh_region: " + s.message());
    *note = "given: " + RegionToString(options->region);
  }
  options->min_component_share = scene.has_masks() ? 1.0 : 0.02;
  *note += scene.has_masks() ? "; clean-up: the largest piece"
                             : "; clean-up: pieces of at least 2% of the largest (no masks)";
  return Status::Ok();
}

namespace {

// The fusion frame of training view `v` rendered with `camera`: depth where the render's alpha
// times the view's mask (if any) is at least 0.5.
DepthFrame RenderFrame(MutualBoostedSolver* solver, const SolverOptions& solver_options,
                       const View& v, const Camera& camera, const SurfaceOptions& options) {
  // The mesh takes the transmitted colour only: no reflected chain.
  ViewRender rendered = RenderView(solver, solver_options, camera, options.surfel_color,
                                   /*transmitted_only=*/true);
  Geometry& g = rendered.geometry;
  DepthFrame f;
  f.camera = camera;
  f.depth = std::move(options.median_depth ? g.median_depth : g.depth);
  f.color = options.surfel_color && solver_options.train_2d ? std::move(rendered.surfel_color)
                                                            : std::move(rendered.appearance.tran);
  f.weight = std::move(g.alpha);
  if (!v.mask.empty()) {
    const Image mask =
        options.resolution_scale == 1 ? v.mask : ResampleMask(v.mask, camera.width, camera.height);
    for (size_t k = 0; k < f.weight.size(); ++k)
      f.weight.data()[k] *= mask.data()[k] >= 0.5f ? 1.0f : 0.0f;
  }
  return f;
}

// A frame's images between processes: depth, colour (3 channels), weight, each of the camera's
// size (the renders always give all three).
Status SendFrame(ViewGroup* group, const DepthFrame& f) {
  for (const Image* im : {&f.depth, &f.color, &f.weight})
    MGSR_RETURN_IF_ERROR(group->Send(0, im->data(), im->size()));
  return Status::Ok();
}

Status ReceiveFrame(ViewGroup* group, int from, const Camera& camera, DepthFrame* f) {
  f->camera = camera;
  f->depth = Image(camera.width, camera.height, 1);
  f->color = Image(camera.width, camera.height, 3);
  f->weight = Image(camera.width, camera.height, 1);
  for (Image* im : {&f->depth, &f->color, &f->weight})
    MGSR_RETURN_IF_ERROR(group->Receive(from, im->data(), im->size()));
  return Status::Ok();
}

}  // namespace

Status ExtractSurface(MutualBoostedSolver* solver, const SolverOptions& solver_options,
                      const Scene& scene, const SurfaceOptions& options, TriangleMesh* mesh,
                      const std::function<void(int, int)>& progress, ViewGroup* group,
                      SeenThroughStats* free_space) {
  if (options.resolution_scale < 1) return Status::Error("mesh resolution scale must be >= 1");
  const std::vector<int> train = scene.TrainIndices();
  const std::vector<Camera> cameras = FusionCameras(scene, options.resolution_scale);
  const int ranks = group != nullptr ? group->size() : 1;
  const int rank = group != nullptr ? group->rank() : 0;
  if (ranks > 1) {
    // Every process meets here once process 0 has come to its mesh (the others wait after
    // training); views go round robin, process 0 fuses them all in order.
    int go = rank == 0 ? 1 : 0;
    MGSR_RETURN_IF_ERROR(group->Max(&go));
  }
  if (rank != 0) {
    for (size_t i = rank; i < train.size(); i += ranks) {
      const DepthFrame f =
          RenderFrame(solver, solver_options, scene.views[train[i]], cameras[i], options);
      MGSR_RETURN_IF_ERROR(SendFrame(group, f));
    }
    return Status::Ok();
  }
  TsdfIntegrator integrator(SurfaceTsdfOptions(scene, options));
  for (size_t i = 0; i < train.size(); ++i) {
    const int owner = static_cast<int>(i % ranks);
    DepthFrame f;
    if (owner == 0) {
      f = RenderFrame(solver, solver_options, scene.views[train[i]], cameras[i], options);
    } else {
      MGSR_RETURN_IF_ERROR(ReceiveFrame(group, owner, cameras[i], &f));
    }
    MGSR_RETURN_IF_ERROR(integrator.Integrate(f));
    if (progress) progress(static_cast<int>(i + 1), static_cast<int>(train.size()));
  }
  MGSR_RETURN_IF_ERROR(integrator.Extract(mesh));
  if (free_space != nullptr) *free_space = integrator.seen_through();
  return Status::Ok();
}

Status ExactDepthCeiling(ExactDepthViews* training_depth, const Scene& scene,
                         const SurfaceOptions& options, TriangleMesh* mesh) {
  const TsdfOptions tsdf = SurfaceTsdfOptions(scene, options);
  const int scale = std::max(1, options.resolution_scale);
  if (scale == 1) return FuseExactDepth(training_depth, tsdf, mesh);
  ExactDepthViews finer(training_depth->caster(), FusionCameras(scene, scale), 0);
  return FuseExactDepth(&finer, tsdf, mesh);
}

SurfaceDepthReport MeasureSurfaceDepth(MutualBoostedSolver* solver,
                                       const SolverOptions& solver_options, const Scene& scene,
                                       ExactDepthViews* training_depth) {
  DepthErrorAccumulator expected, median;
  NormalErrorAccumulator normal;
  const std::vector<int> train = scene.TrainIndices();
  for (size_t k = 0; k < train.size(); ++k) {
    const View& v = scene.views[train[k]];
    const ViewRender r = RenderView(solver, solver_options, v.camera, true);
    const Image truth = training_depth->Depth(k);
    const Image* mask = v.mask.empty() ? nullptr : &v.mask;
    expected.Add(r.geometry.depth, truth, mask, v.camera);
    median.Add(r.geometry.median_depth, truth, mask, v.camera);
    if (!r.geometry.normal_world.empty()) {
      const Image true_normal = RenderExactNormal(training_depth->caster(), v.camera);
      normal.Add(r.geometry.normal_world, true_normal, mask, v.camera);
    }
  }
  return {expected.Finish(), median.Finish(), normal.Finish()};
}

}  // namespace mgsr
