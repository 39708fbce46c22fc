// Ground-truth geometry of a scene folder, when it has any: the mesh (mgsr_synth's gt/mesh.ply or
// a Blender-style gt_mesh.ply beside the images) and, optionally, samples of its visible part
// (gt_points_visible.ply) to measure completeness against what some camera sees.
#pragma once

#include <string>

#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

struct GroundTruthGeometry {
  std::string mesh_path;  // empty: the scene has no ground-truth mesh
  TriangleMesh mesh;
  std::string visible_path;  // empty: no visible-points file
  TriangleMesh visible_points;
  bool found() const { return !mesh_path.empty(); }
};

// Looks in `scene_root` for gt/mesh.ply, then gt_mesh.ply, and for gt_points_visible.ply.
// Finding none is not an error (found() is false); a file that exists but cannot be read is.
Status FindGroundTruth(const std::string& scene_root, GroundTruthGeometry* gt);

}  // namespace mgsr
