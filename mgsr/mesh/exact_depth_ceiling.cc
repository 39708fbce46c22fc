#include "mgsr/mesh/exact_depth_ceiling.h"

#include <utility>

#include "mgsr/synth/ray_caster.h"

namespace mgsr {

Image RenderExactDepth(const RayCaster& caster, const Camera& camera) {
  Image depth(camera.width, camera.height, 1, 0.0f);
  const Eigen::Vector3d origin = camera.Center();
  const Eigen::Matrix3d Rt = camera.R.transpose();
#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      // Direction with camera-space z = 1: the hit distance is the z-depth.
      const Eigen::Vector3d d = Rt * camera.PixelToRay(x + 0.5, y + 0.5);
      RayHit hit;
      if (caster.Intersect(origin, d, 1e-9, 1e9, &hit))
        depth.at(0, y, x) = static_cast<float>(hit.t);
    }
  }
  return depth;
}

ExactDepthViews::ExactDepthViews(const RayCaster& caster, std::vector<Camera> cameras,
                                 size_t max_bytes)
    : caster_(caster),
      cameras_(std::move(cameras)),
      kept_(cameras_.size()),
      max_bytes_(max_bytes) {}

Image ExactDepthViews::Depth(size_t k) {
  if (!kept_[k].empty()) return kept_[k];
  Image depth = RenderExactDepth(caster_, cameras_[k]);
  const size_t bytes = depth.size() * sizeof(float);
  if (kept_bytes_ + bytes <= max_bytes_) {
    kept_[k] = depth;
    kept_bytes_ += bytes;
  }
  return depth;
}

Status FuseExactDepth(ExactDepthViews* views, const TsdfOptions& options, TriangleMesh* mesh) {
  if (!(options.voxel_size > 0)) return Status::Error("exact-depth ceiling: no voxel size given");
  TsdfIntegrator integrator(options);
  for (size_t k = 0; k < views->size(); ++k) {
    DepthFrame f;
    f.camera = views->camera(k);
    f.depth = views->Depth(k);
    MGSR_RETURN_IF_ERROR(integrator.Integrate(f));
  }
  return integrator.Extract(mesh);
}

Status FuseExactDepth(const TriangleMesh& ground_truth, const std::vector<Camera>& cameras,
                      const TsdfOptions& options, TriangleMesh* mesh) {
  if (ground_truth.empty()) return Status::Error("exact-depth ceiling: the ground truth is empty");
  if (!(options.voxel_size > 0)) return Status::Error("exact-depth ceiling: no voxel size given");
  const RayCaster caster(ground_truth);
  ExactDepthViews views(caster, cameras, 0);
  return FuseExactDepth(&views, options, mesh);
}

}  // namespace mgsr
