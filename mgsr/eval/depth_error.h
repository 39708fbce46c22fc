// Signed per-pixel depth error against exact depth (docs/design.md): where a rendered depth
// lies relative to the true surface, pooled over views. The sign follows the mesh's signed offset:
// error = true depth - rendered depth, so a negative error means the render lies behind the true
// surface (inside the object). A mean absolute error is dominated by a few silhouette pixels; the
// median and the share of pixels more than one pixel footprint off say more.
#pragma once

#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"

namespace mgsr {

struct DepthErrorStats {
  size_t pixels = 0;
  double median = 0, mean = 0;   // scene units, signed (negative: behind the true surface)
  double median_footprints = 0;  // the median in pixel footprints (depth / focal length)
  double mean_abs = 0;
  double share_beyond_footprint = 0;  // share of pixels more than one footprint off
};

class DepthErrorAccumulator {
 public:
  // Pixels count where the true depth is positive, the rendered depth is finite and positive, and
  // the mask (optional, 1 channel) is at least 0.5.
  void Add(const Image& rendered, const Image& truth, const Image* mask, const Camera& camera);
  DepthErrorStats Finish() const;

 private:
  std::vector<double> error_, footprints_;
};

// The same signed error as a picture (3 channels): white where the render lies on the true surface,
// red where it lies in front of it (outside the object), blue behind it (inside), saturating at
// `range_footprints` pixel footprints; black where a pixel does not count (as in Add). This is the
// map that shows where a surface is filled in (concavities) or sunk (convex parts): docs/
// geometry.md.
Image SignedDepthErrorImage(const Image& rendered, const Image& truth, const Image* mask,
                            const Camera& camera, double range_footprints = 2.0);

}  // namespace mgsr
