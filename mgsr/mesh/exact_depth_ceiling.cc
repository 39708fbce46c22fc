#include "mgsr/mesh/exact_depth_ceiling.h"

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

Status FuseExactDepth(const TriangleMesh& ground_truth, const std::vector<Camera>& cameras,
                      const TsdfOptions& options, TriangleMesh* mesh) {
  if (ground_truth.empty()) return Status::Error("exact-depth ceiling: the ground truth is empty");
  if (!(options.voxel_size > 0)) return Status::Error("exact-depth ceiling: no voxel size given");
  const RayCaster caster(ground_truth);
  TsdfIntegrator integrator(options);
  for (const Camera& camera : cameras) {
    DepthFrame f;
    f.camera = camera;
    f.depth = RenderExactDepth(caster, camera);
    MGSR_RETURN_IF_ERROR(integrator.Integrate(f));
  }
  return integrator.Extract(mesh);
}

}  // namespace mgsr
