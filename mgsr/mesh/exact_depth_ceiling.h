// The achievable ceiling of a reconstruction's mesh (docs/design.md): the ground-truth mesh's
// exact depth, rendered for the same cameras at the same resolution and fused with the same TSDF
// settings. Whatever the fusion itself loses (voxel steps, truncation, unseen regions) this mesh
// loses too, so a reconstruction's score reads as "x of the achievable".
#pragma once

#include <cstddef>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"
#include "mgsr/mesh/tsdf_fusion.h"

namespace mgsr {

class RayCaster;

// Exact z-depth of `caster`'s mesh at every pixel centre of `camera` (0 where the ray misses).
Image RenderExactDepth(const RayCaster& caster, const Camera& camera);

// The exact depth of one ground truth for a fixed list of cameras, ray-cast once per camera and
// kept for the next reader while the images kept stay within `max_bytes` (past that, cast again
// each time). A run with a ground truth reads the training views' exact depth three times: the
// depth check after the warm-up, the exact-depth ceiling and the check at the end.
class ExactDepthViews {
 public:
  static constexpr size_t kDefaultMaxBytes = size_t{512} << 20;

  // `caster` must outlive this.
  ExactDepthViews(const RayCaster& caster, std::vector<Camera> cameras,
                  size_t max_bytes = kDefaultMaxBytes);

  const RayCaster& caster() const { return caster_; }
  size_t size() const { return cameras_.size(); }
  const Camera& camera(size_t k) const { return cameras_[k]; }
  // RenderExactDepth of camera k (the same image whether kept or cast again).
  Image Depth(size_t k);
  size_t kept_bytes() const { return kept_bytes_; }

 private:
  const RayCaster& caster_;
  std::vector<Camera> cameras_;
  std::vector<Image> kept_;  // empty until first read (or when over the budget)
  size_t max_bytes_, kept_bytes_ = 0;
};

// Fuses the exact depth of every camera of `views` with `options` (whose voxel size must be set:
// the one the reconstruction used), one view at a time.
Status FuseExactDepth(ExactDepthViews* views, const TsdfOptions& options, TriangleMesh* mesh);
// The same for a mesh and cameras, nothing kept.
Status FuseExactDepth(const TriangleMesh& ground_truth, const std::vector<Camera>& cameras,
                      const TsdfOptions& options, TriangleMesh* mesh);

}  // namespace mgsr
