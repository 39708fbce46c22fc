// The photo-pipeline flags shared by mgsr_colmap and `mgsr_solve --images`, and the summary both
// print.
#pragma once

#include <gflags/gflags.h>

#include <cstdio>

#include "mgsr/sfm/colmap_pipeline.h"

DEFINE_string(colmap, "colmap", "The colmap program (name on PATH, or a path).");
DEFINE_bool(per_image_cameras, false,
            "One camera per photo (zoom or several cameras) instead of one shared camera.");
DEFINE_string(camera_model, "SIMPLE_RADIAL",
              "Camera model the mapper fits before undistortion (SIMPLE_PINHOLE, PINHOLE, "
              "SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV).");
DEFINE_int32(exhaustive_max_images, 100,
             "Match every pair up to this many photos; above it, sequential matching.");
DEFINE_int32(max_image_size, 2000, "SIFT runs on photos downscaled to this longest side.");

namespace mgsr_tools {

inline mgsr::ColmapPipelineOptions ColmapOptionsFromFlags() {
  mgsr::ColmapPipelineOptions o;
  o.colmap = FLAGS_colmap;
  o.single_camera = !FLAGS_per_image_cameras;
  o.camera_model = FLAGS_camera_model;
  o.exhaustive_max_images = FLAGS_exhaustive_max_images;
  o.max_image_size = FLAGS_max_image_size;
  o.log = [](const std::string& line) {
    std::printf("colmap: %s\n", line.c_str());
    std::fflush(stdout);
  };
  return o;
}

inline void PrintColmapSummary(const mgsr::ColmapPipelineSummary& s) {
  double total = 0;
  for (const auto& step : s.steps) total += step.seconds;
  std::printf(
      "colmap: registered %d of %d photos, %ld points, mean reprojection error %.3f px, "
      "%.1f s in all\n",
      s.images_registered, s.images_given, s.points, s.mean_reprojection_error, total);
  if (!s.unregistered.empty()) {
    std::printf("colmap: not registered (left out):");
    for (const std::string& n : s.unregistered) std::printf(" %s", n.c_str());
    std::printf("\n");
  }
  if (s.num_models > 1) {
    std::printf("colmap: the mapper made %d separate models; the largest is used\n", s.num_models);
  }
  std::fflush(stdout);
}

}  // namespace mgsr_tools
