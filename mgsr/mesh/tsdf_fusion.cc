#include "mgsr/mesh/tsdf_fusion.h"

#include <omp.h>
#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>

#include <algorithm>
#include <cmath>

namespace mgsr {

double AutoVoxelSize(const std::vector<DepthFrame>& frames, const Eigen::Vector3d& center) {
  std::vector<double> footprints;
  for (const DepthFrame& f : frames) {
    footprints.push_back((f.camera.Center() - center).norm() / std::max(f.camera.fx, f.camera.fy));
  }
  if (footprints.empty()) return 0.01;
  std::nth_element(footprints.begin(), footprints.begin() + footprints.size() / 2,
                   footprints.end());
  return footprints[footprints.size() / 2];
}

Status FuseDepthMaps(const std::vector<DepthFrame>& frames, const TsdfOptions& options,
                     TriangleMesh* mesh) {
  if (frames.empty()) return Status::Error("TSDF fusion: no depth maps");
  double depth_max = options.depth_max;
  for (const DepthFrame& f : frames) {
    if (f.depth.channels() != 1 || f.depth.width() != f.camera.width ||
        f.depth.height() != f.camera.height) {
      return Status::Error("TSDF fusion: depth map does not match its camera");
    }
    if (options.depth_max <= 0) {
      for (size_t i = 0; i < f.depth.size(); ++i) {
        if (std::isfinite(f.depth.data()[i]))
          depth_max = std::max<double>(depth_max, f.depth.data()[i]);
      }
    }
  }
  if (!(depth_max > 0)) return Status::Error("TSDF fusion: every depth map is empty");
  double voxel = options.voxel_size;
  if (voxel <= 0) {
    // Centre of the observed points: average of the back-projected centre pixels is cheap and
    // robust.
    Eigen::Vector3d center = Eigen::Vector3d::Zero();
    int n = 0;
    for (const DepthFrame& f : frames) {
      const float z = f.depth.at(0, f.camera.height / 2, f.camera.width / 2);
      if (z > 0 && std::isfinite(z)) {
        center += f.camera.CameraToWorld(
            f.camera.PixelToRay(f.camera.width / 2.0, f.camera.height / 2.0) * z);
        ++n;
      }
    }
    voxel = AutoVoxelSize(frames, n > 0 ? Eigen::Vector3d(center / n) : Eigen::Vector3d::Zero());
  }
  open3d::pipelines::integration::ScalableTSDFVolume volume(
      voxel, options.truncation_voxels * voxel,
      open3d::pipelines::integration::TSDFVolumeColorType::RGB8);
  // Open3D 0.16's integrate is far slower with two OpenMP threads than with one on this machine
  // (DESIGN.md section 2): run it single-threaded.
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  for (const DepthFrame& f : frames) {
    const int w = f.camera.width, h = f.camera.height;
    open3d::geometry::Image depth, color;
    depth.Prepare(w, h, 1, 4);
    color.Prepare(w, h, 3, 1);
    const bool has_color = f.color.channels() == 3 && f.color.width() == w && f.color.height() == h;
    const bool has_weight =
        f.weight.channels() == 1 && f.weight.width() == w && f.weight.height() == h;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        float z = f.depth.at(0, y, x);
        if (!std::isfinite(z) || z <= 0 ||
            (has_weight && f.weight.at(0, y, x) < options.weight_threshold))
          z = 0;
        *depth.PointerAt<float>(x, y) = z;
        for (int c = 0; c < 3; ++c) {
          const float v = has_color ? f.color.at(c, y, x) : 0.7f;
          *color.PointerAt<uint8_t>(x, y, c) =
              static_cast<uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255));
        }
      }
    }
    auto rgbd = open3d::geometry::RGBDImage::CreateFromColorAndDepth(color, depth, 1.0,
                                                                     depth_max * 1.01, false);
    // Open3D puts pixel centres at integer coordinates; COLMAP at half-integers.
    const open3d::camera::PinholeCameraIntrinsic intrinsic(w, h, f.camera.fx, f.camera.fy,
                                                           f.camera.cx - 0.5, f.camera.cy - 0.5);
    volume.Integrate(*rgbd, intrinsic, f.camera.WorldToCameraMatrix());
  }
  auto result = volume.ExtractTriangleMesh();
  omp_set_num_threads(threads);
  if (options.keep_largest_component && !result->triangles_.empty()) {
    std::vector<int> cluster;
    std::vector<size_t> sizes;
    std::vector<double> areas;
    std::tie(cluster, sizes, areas) = result->ClusterConnectedTriangles();
    const int largest =
        static_cast<int>(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
    std::vector<bool> remove(cluster.size());
    for (size_t i = 0; i < cluster.size(); ++i) remove[i] = cluster[i] != largest;
    result->RemoveTrianglesByMask(remove);
    result->RemoveUnreferencedVertices();
  }
  result->ComputeVertexNormals();
  *mesh = TriangleMesh();
  mesh->vertices = result->vertices_;
  for (const auto& t : result->triangles_) mesh->triangles.push_back(t);
  mesh->vertex_normals = result->vertex_normals_;
  for (const auto& c : result->vertex_colors_) mesh->vertex_colors.push_back(c.cast<float>());
  return Status::Ok();
}

}  // namespace mgsr
