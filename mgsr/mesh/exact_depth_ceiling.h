// The achievable ceiling of a reconstruction's mesh (DESIGN.md section 6): the ground-truth mesh's
// exact depth, rendered for the same cameras at the same resolution and fused with the same TSDF
// settings. Whatever the fusion itself loses (voxel steps, truncation, unseen regions) this mesh
// loses too, so a reconstruction's score reads as "x of the achievable".
#pragma once

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

// Fuses the exact depth of `ground_truth` seen from `cameras` with `options` (whose voxel size
// must be set: the one the reconstruction used), one view at a time.
Status FuseExactDepth(const TriangleMesh& ground_truth, const std::vector<Camera>& cameras,
                      const TsdfOptions& options, TriangleMesh* mesh);

}  // namespace mgsr
