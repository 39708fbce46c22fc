#include "mgsr/eval/ground_truth.h"

#include "mgsr/io/file_util.h"
#include "mgsr/io/ply.h"

namespace mgsr {

Status FindGroundTruth(const std::string& scene_root, GroundTruthGeometry* gt) {
  *gt = GroundTruthGeometry();
  for (const char* name : {"gt/mesh.ply", "gt_mesh.ply"}) {
    const std::string path = JoinPath(scene_root, name);
    if (!FileExists(path)) continue;
    MGSR_RETURN_IF_ERROR(ReadTriangleMesh(path, &gt->mesh));
    gt->mesh_path = path;
    break;
  }
  const std::string visible = JoinPath(scene_root, "gt_points_visible.ply");
  if (gt->found() && FileExists(visible)) {
    MGSR_RETURN_IF_ERROR(ReadTriangleMesh(visible, &gt->visible_points));
    gt->visible_path = visible;
  }
  return Status::Ok();
}

}  // namespace mgsr
