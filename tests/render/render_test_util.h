// Helpers shared by the renderer tests.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"

namespace mgsr::testing {

// A small camera 3 units from the origin, looking at it (the random test scenes sit around it).
inline Camera RenderTestCamera(int w = 24, int h = 24) {
  return LookAtCamera({0.3, -3.0, 0.4}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), w, h, 30.0 * w / 24,
                      30.0 * h / 24);
}

inline double MaxAbsDiff(const Image& im, const std::vector<double>& ref) {
  double d = 0;
  for (size_t i = 0; i < im.size(); ++i) d = std::max(d, std::abs(im.data()[i] - ref[i]));
  return d;
}

}  // namespace mgsr::testing
