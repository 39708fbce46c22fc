// mgsr_colmap: photos -> undistorted COLMAP workspace, running the real `colmap` program headless
// on the CPU (feature extraction, matching, mapping, undistortion). The result (WORKSPACE/dense) is
// what mgsr_solve --workspace reads.
#include <gflags/gflags.h>

#include <cstdio>

#include "tools/colmap_flags.h"
#include "tools/openmp_wait.h"
#include "tools/tool_flags.h"

DEFINE_string(images, "", "Folder of photos.");
DEFINE_string(masks, "", "Optional folder of foreground masks (<stem>.png).");
DEFINE_string(workspace, "", "Output folder (created).");

int main(int argc, char** argv) {
  mgsr_tools::PreferShortOpenMpSpins(argv);
  mgsr_tools::ParseToolFlags("mgsr_colmap --images DIR --workspace DIR [--masks DIR] [options]",
                             {{"Input and output", {"images", "masks", "workspace"}},
                              {"COLMAP",
                               {"colmap", "per_image_cameras", "camera_model",
                                "exhaustive_max_images", "max_image_size"}}},
                             &argc, &argv);
  mgsr::ColmapPipelineOptions options = mgsr_tools::ColmapOptionsFromFlags();
  options.images = FLAGS_images;
  options.masks = FLAGS_masks;
  options.workspace = FLAGS_workspace;
  mgsr::ColmapPipelineSummary summary;
  const mgsr::Status s = mgsr::RunColmapPipeline(options, &summary);
  if (!s.ok()) {
    std::fprintf(stderr, "error: %s\n", s.message().c_str());
    return 1;
  }
  mgsr_tools::PrintColmapSummary(summary);
  std::printf("workspace for mgsr_solve: %s\n", summary.scene_dir.c_str());
  return 0;
}
