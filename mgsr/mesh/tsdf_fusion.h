// TSDF fusion of per-view depth maps into a triangle mesh (method.md 5; docs/design.md), on
// Open3D's ScalableTSDFVolume from Debian's libopen3d-dev.
#pragma once

#include <Eigen/Geometry>
#include <memory>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"
#include "mgsr/mesh/seen_through.h"

namespace mgsr {

// One view to fuse. Depth is camera-space z per pixel (0 = no depth). Pixels are dropped where
// `weight` (alpha or mask, optional) is below the threshold.
struct DepthFrame {
  Camera camera;
  Image depth;   // 1 channel
  Image color;   // 3 channels in [0, 1], optional (grey mesh without it)
  Image weight;  // 1 channel, optional
};

struct TsdfOptions {
  double voxel_size = 0;         // 0: the pixel footprint at the object (AutoVoxelSize)
  double truncation_voxels = 4;  // sdf truncation in voxels (4: best NC, docs/user_guide.md)
  double depth_max = 0;          // 0: beyond every depth in the frames
  float weight_threshold = 0.5f;
  bool keep_largest_component = false;  // drop floating fragments
  // With keep_largest_component: also keep every other component of at least this share of the
  // largest one's triangles (1: the largest alone). A scene's object need not touch its ground.
  double min_component_share = 1.0;
  // Remove the vertices that more views see through than hold (seen_through.h): what a view
  // renders nothing at, or sees well behind, is free space. Keeps each view's depth (4 bytes a
  // pixel) until the mesh is extracted.
  bool free_space = true;
  // When not empty, what is meshed (fusion_region.h): depth whose point lies outside this box
  // grown by the truncation band is not fused, and triangles with a vertex outside the box are
  // removed before the clean-up (so the largest component is one inside it).
  Eigen::AlignedBox3d region;
};

// The median over views of (distance from the camera to `center`) / focal length: one voxel per
// pixel footprint at the object, finer than which fusion only adds depth-pixel steps.
double AutoVoxelSize(const std::vector<Camera>& cameras, const Eigen::Vector3d& center);
double AutoVoxelSize(const std::vector<DepthFrame>& frames, const Eigen::Vector3d& center);

// The point nearest (least squares) to every camera's optical axis: what an object capture looks
// at. The mean of the camera centres when the axes are (nearly) parallel.
Eigen::Vector3d LookAtCenter(const std::vector<Camera>& cameras);

// Fuses frames one at a time, so that large (e.g. super-resolved) depth maps need not all be held
// in memory. The voxel must be given (options.voxel_size > 0).
class TsdfIntegrator {
 public:
  explicit TsdfIntegrator(const TsdfOptions& options);
  ~TsdfIntegrator();
  Status Integrate(const DepthFrame& frame);
  // The mesh of everything integrated so far; an error when no depth was integrated.
  Status Extract(TriangleMesh* mesh);
  // What the free-space test removed in the last Extract.
  const SeenThroughStats& seen_through() const { return seen_through_; }

 private:
  struct Volume;
  TsdfOptions options_;
  std::unique_ptr<Volume> volume_;
  bool any_depth_ = false;
  SeenThroughVotes votes_;
  SeenThroughStats seen_through_;
};

// All frames at once. With options.voxel_size 0 the voxel is AutoVoxelSize around the centre of
// what the frames' centre pixels see.
Status FuseDepthMaps(const std::vector<DepthFrame>& frames, const TsdfOptions& options,
                     TriangleMesh* mesh);

}  // namespace mgsr
