// Neighbouring views for multi-view loss terms, chosen once per scene: for each training view, the
// training views that see the most of the same scene points from a useful angle. Two views looking
// at a point from nearly the same place (no baseline) or from far apart (different sides, large
// perspective change) say little about its depth; a triangulation angle near `preferred_angle_deg`
// (MVS practice: 5-20 degrees) weighs most. Points stand for tracks: each counts for a pair when it
// projects inside both frames in front of both cameras. Without points, the scene centre is the one
// point (camera angles alone decide).
#pragma once

#include <vector>

#include "mgsr/io/scene.h"

namespace mgsr {

struct NeighbourOptions {
  int count = 2;                    // neighbours per view (at most kMaxNeighbours of the loss)
  double preferred_angle_deg = 12;  // the triangulation angle that weighs most
  double min_angle_deg = 2;         // pairs below this angle at a point do not count it
  double max_angle_deg = 45;        // nor above this one
  int max_points = 4000;            // points used (an even subsample of the scene's)
};

// neighbours[v] lists up to options.count training views for every view v (train and test), best
// first; empty for a view no other training view shares points with. Deterministic.
std::vector<std::vector<int>> SelectNeighbours(const Scene& scene, const NeighbourOptions& options);

}  // namespace mgsr
