// Angle between rendered and true surface normals, pooled over views: where geometry copies
// texture or shading (a flat printed wall whose normals wobble) or smooths away relief, this shows
// it directly, without going through a mesh.
#pragma once

#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"

namespace mgsr {

class RayCaster;

struct NormalErrorStats {
  size_t pixels = 0;
  double mean_deg = 0, median_deg = 0;
  double share_beyond_10deg = 0;
};

// Unit world-space face normals of `caster`'s mesh at the pixel centres of `camera`, turned to
// face the camera (3 channels; 0 where the ray misses).
Image RenderExactNormal(const RayCaster& caster, const Camera& camera);

class NormalErrorAccumulator {
 public:
  // Pixels count where the true normal is set, the rendered normal (any length: an alpha-weighted
  // normal is normalised here) is non-zero and the mask (optional) is at least 0.5. Both are
  // turned to face the camera before the angle is taken.
  void Add(const Image& rendered, const Image& truth, const Image* mask, const Camera& camera);
  NormalErrorStats Finish() const;

 private:
  std::vector<float> angles_deg_;
};

}  // namespace mgsr
