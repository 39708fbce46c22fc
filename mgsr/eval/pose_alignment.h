// Comparing recovered camera poses with ground truth: structure from motion finds poses only up to
// a similarity (scale, rotation, translation), so the two sets are aligned first (Umeyama on the
// camera centres) and then compared.
#pragma once

#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/status.h"

namespace mgsr {

struct PoseErrors {
  int num_poses = 0;
  double scale = 1;  // ground truth = scale * R * estimate + t
  double mean_rotation_deg = 0, max_rotation_deg = 0;
  // Camera-centre distances after alignment, divided by the ground-truth extent (the largest
  // distance of a ground-truth camera centre from their centroid).
  double mean_translation_rel = 0, max_translation_rel = 0;
  std::vector<double> rotation_deg, translation_rel;  // per pose
};

// Aligns `estimate` to `truth` (same length, matched by index, at least 3 non-collinear centres)
// and measures the remaining rotation and centre errors.
Status ComparePoses(const std::vector<Camera>& estimate, const std::vector<Camera>& truth,
                    PoseErrors* errors);

}  // namespace mgsr
