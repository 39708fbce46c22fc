// mgsr_colmap: photos -> undistorted COLMAP workspace, running the real `colmap` program headless
// on the CPU (feature extraction, matching, mapping, undistortion). The result (WORKSPACE/dense) is
// what mgsr_solve --workspace reads.
#include <gflags/gflags.h>

#include <cstdio>

#include "tools/colmap_flags.h"

DEFINE_string(images, "", "Folder of photos.");
DEFINE_string(masks, "", "Optional folder of foreground masks (<stem>.png).");
DEFINE_string(workspace, "", "Output folder (created).");

int main(int argc, char** argv) {
  gflags::SetUsageMessage("mgsr_colmap --images DIR --workspace DIR [--masks DIR] [options]");
  gflags::ParseCommandLineFlags(&argc, &argv, true);
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
