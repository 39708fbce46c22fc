#include "mgsr/mesh/tsdf_fusion.h"

#include <omp.h>
#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "mgsr/mesh/fusion_region.h"

namespace mgsr {

double AutoVoxelSize(const std::vector<Camera>& cameras, const Eigen::Vector3d& center) {
  std::vector<double> footprints;
  for (const Camera& c : cameras)
    footprints.push_back((c.Center() - center).norm() / std::max(c.fx, c.fy));
  if (footprints.empty()) return 0.01;
  std::nth_element(footprints.begin(), footprints.begin() + footprints.size() / 2,
                   footprints.end());
  return footprints[footprints.size() / 2];
}

double AutoVoxelSize(const std::vector<DepthFrame>& frames, const Eigen::Vector3d& center) {
  std::vector<Camera> cameras;
  for (const DepthFrame& f : frames) cameras.push_back(f.camera);
  return AutoVoxelSize(cameras, center);
}

Eigen::Vector3d LookAtCenter(const std::vector<Camera>& cameras) {
  // Minimise sum_i |(I - d_i d_i^T)(x - c_i)|^2 over x.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero(), mean = Eigen::Vector3d::Zero();
  for (const Camera& c : cameras) {
    const Eigen::Vector3d d = c.R.row(2).transpose().normalized();  // optical axis in the world
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * c.Center();
    mean += c.Center();
  }
  if (cameras.empty()) return Eigen::Vector3d::Zero();
  mean /= static_cast<double>(cameras.size());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  if (!(eig.eigenvalues().minCoeff() > 1e-6 * std::max(1.0, eig.eigenvalues().maxCoeff())))
    return mean;
  return A.ldlt().solve(b);
}

struct TsdfIntegrator::Volume {
  Volume(double voxel, double truncation)
      : tsdf(voxel, truncation, open3d::pipelines::integration::TSDFVolumeColorType::RGB8) {}
  open3d::pipelines::integration::ScalableTSDFVolume tsdf;
};

TsdfIntegrator::TsdfIntegrator(const TsdfOptions& options)
    : options_(options),
      volume_(std::make_unique<Volume>(options.voxel_size,
                                       options.truncation_voxels * options.voxel_size)) {}

TsdfIntegrator::~TsdfIntegrator() = default;

Status TsdfIntegrator::Integrate(const DepthFrame& f) {
  if (!(options_.voxel_size > 0)) return Status::Error("TSDF fusion: the voxel size is not set");
  const int w = f.camera.width, h = f.camera.height;
  if (f.depth.channels() != 1 || f.depth.width() != w || f.depth.height() != h)
    return Status::Error("TSDF fusion: depth map does not match its camera");
  open3d::geometry::Image depth, color;
  depth.Prepare(w, h, 1, 4);
  color.Prepare(w, h, 3, 1);
  const bool has_color = f.color.channels() == 3 && f.color.width() == w && f.color.height() == h;
  const bool has_weight =
      f.weight.channels() == 1 && f.weight.width() == w && f.weight.height() == h;
  double frame_max = 0;
  const bool clip = !options_.region.isEmpty();
  Eigen::AlignedBox3d reach = options_.region;
  if (clip) {
    const double band = options_.truncation_voxels * options_.voxel_size;
    reach.min() -= Eigen::Vector3d::Constant(band);
    reach.max() += Eigen::Vector3d::Constant(band);
  }
  // The free-space votes take the depth before the region's clip: what a view sees beyond the
  // region is still behind whatever it sees through.
  std::vector<float> seen;
  if (options_.free_space) seen.resize(static_cast<size_t>(w) * h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      float z = f.depth.at(0, y, x);
      if (!std::isfinite(z) || z <= 0 ||
          (has_weight && f.weight.at(0, y, x) < options_.weight_threshold))
        z = 0;
      if (!seen.empty()) seen[static_cast<size_t>(y) * w + x] = z;
      if (z > 0 && clip &&
          !reach.contains(f.camera.CameraToWorld(f.camera.PixelToRay(x + 0.5, y + 0.5) * z)))
        z = 0;
      frame_max = std::max<double>(frame_max, z);
      *depth.PointerAt<float>(x, y) = z;
      for (int c = 0; c < 3; ++c) {
        const float v = has_color ? f.color.at(c, y, x) : 0.7f;
        *color.PointerAt<uint8_t>(x, y, c) =
            static_cast<uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255));
      }
    }
  }
  if (!seen.empty()) votes_.AddView(f.camera, std::move(seen));
  if (frame_max <= 0) return Status::Ok();  // nothing to fuse from this view
  any_depth_ = true;
  const double depth_max = options_.depth_max > 0 ? options_.depth_max : frame_max * 1.01;
  auto rgbd =
      open3d::geometry::RGBDImage::CreateFromColorAndDepth(color, depth, 1.0, depth_max, false);
  // Open3D puts pixel centres at integer coordinates; COLMAP at half-integers.
  const open3d::camera::PinholeCameraIntrinsic intrinsic(w, h, f.camera.fx, f.camera.fy,
                                                         f.camera.cx - 0.5, f.camera.cy - 0.5);
  // Open3D 0.16's integrate is far slower with two OpenMP threads than with one on this machine
  // (docs/design.md): run it single-threaded.
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  volume_->tsdf.Integrate(*rgbd, intrinsic, f.camera.WorldToCameraMatrix());
  omp_set_num_threads(threads);
  return Status::Ok();
}

namespace {

// The triangles outside the edge-connected components kept: the largest (by triangle count; of
// equal ones, the one holding the lowest triangle index, as Open3D's ClusterConnectedTriangles
// would choose) and, with min_share < 1, every other one of at least min_share of its size. By
// sorting the edges and a union-find instead of Open3D's hash map of edge lists (0.4 s -> a few
// ms for 200k triangles).
std::vector<bool> OutsideKeptComponents(const std::vector<Eigen::Vector3i>& triangles,
                                        double min_share) {
  const size_t n = triangles.size();
  std::vector<uint32_t> parent(n);
  for (size_t t = 0; t < n; ++t) parent[t] = static_cast<uint32_t>(t);
  auto find = [&](uint32_t t) {
    while (parent[t] != t) t = parent[t] = parent[parent[t]];
    return t;
  };
  // Every edge as (smaller vertex, larger vertex, triangle); triangles sharing an edge are joined.
  std::vector<std::pair<uint64_t, uint32_t>> edges;
  edges.reserve(3 * n);
  for (size_t t = 0; t < n; ++t) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = static_cast<uint32_t>(triangles[t][k]);
      const uint32_t b = static_cast<uint32_t>(triangles[t][(k + 1) % 3]);
      edges.emplace_back((static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b),
                         static_cast<uint32_t>(t));
    }
  }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 1; i < edges.size(); ++i) {
    if (edges[i].first != edges[i - 1].first) continue;
    const uint32_t a = find(edges[i].second), b = find(edges[i - 1].second);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);  // the root is the lowest triangle
  }
  std::vector<uint32_t> size(n, 0);
  for (size_t t = 0; t < n; ++t) ++size[find(static_cast<uint32_t>(t))];
  uint32_t largest = 0;
  for (size_t t = 0; t < n; ++t) {
    if (size[t] > size[largest]) largest = static_cast<uint32_t>(t);
  }
  std::vector<bool> outside(n);
  for (size_t t = 0; t < n; ++t) {
    const uint32_t root = find(static_cast<uint32_t>(t));
    outside[t] = root != largest && (min_share >= 1 || size[root] < min_share * size[largest]);
  }
  return outside;
}

}  // namespace

Status TsdfIntegrator::Extract(TriangleMesh* mesh) {
  if (!any_depth_) return Status::Error("TSDF fusion: every depth map is empty");
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  auto result = volume_->tsdf.ExtractTriangleMesh();
  omp_set_num_threads(threads);
  seen_through_ = SeenThroughStats();
  if (options_.free_space && !result->triangles_.empty()) {
    result->RemoveTrianglesByMask(votes_.TrianglesSeenThrough(
        result->vertices_, result->triangles_, options_.truncation_voxels * options_.voxel_size,
        &seen_through_));
    result->RemoveUnreferencedVertices();
  }
  if (!options_.region.isEmpty()) {
    result->RemoveTrianglesByMask(
        TrianglesOutside(options_.region, result->vertices_, result->triangles_));
    result->RemoveUnreferencedVertices();
  }
  if (options_.keep_largest_component && !result->triangles_.empty()) {
    result->RemoveTrianglesByMask(
        OutsideKeptComponents(result->triangles_, options_.min_component_share));
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

namespace {

// The voxel FuseDepthMaps uses: options.voxel_size, or (when 0) AutoVoxelSize around the centre of
// what the frames' centre pixels see.
double ResolveVoxelSize(const std::vector<DepthFrame>& frames, const TsdfOptions& options) {
  if (options.voxel_size > 0) return options.voxel_size;
  // Centre of the observed points: the average of the back-projected centre pixels is cheap and
  // robust.
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  int n = 0;
  for (const DepthFrame& f : frames) {
    if (f.depth.channels() != 1 || f.depth.width() != f.camera.width ||
        f.depth.height() != f.camera.height)
      continue;
    const float z = f.depth.at(0, f.camera.height / 2, f.camera.width / 2);
    if (z > 0 && std::isfinite(z)) {
      center += f.camera.CameraToWorld(
          f.camera.PixelToRay(f.camera.width / 2.0, f.camera.height / 2.0) * z);
      ++n;
    }
  }
  return AutoVoxelSize(frames, n > 0 ? Eigen::Vector3d(center / n) : Eigen::Vector3d::Zero());
}

}  // namespace

Status FuseDepthMaps(const std::vector<DepthFrame>& frames, const TsdfOptions& options,
                     TriangleMesh* mesh) {
  if (frames.empty()) return Status::Error("TSDF fusion: no depth maps");
  for (const DepthFrame& f : frames) {
    if (f.depth.channels() != 1 || f.depth.width() != f.camera.width ||
        f.depth.height() != f.camera.height) {
      return Status::Error("TSDF fusion: depth map does not match its camera");
    }
  }
  TsdfOptions resolved = options;
  resolved.voxel_size = ResolveVoxelSize(frames, options);
  TsdfIntegrator integrator(resolved);
  for (const DepthFrame& f : frames) MGSR_RETURN_IF_ERROR(integrator.Integrate(f));
  return integrator.Extract(mesh);
}

}  // namespace mgsr
