#pragma once
// The backdrop of photos taken without masks or alpha. Such photos keep their own background in
// every pixel, while the renderers composite on a fixed grey level (2DGS white, 3DGS black); the
// branches then paint the backdrop with primitives scattered in front of and around the object,
// and the TSDF fuses them into the mesh. When the backdrop is a uniform grey (a studio sweep, a
// turntable), rendering both branches on that grey leaves empty space empty.

#include <string>

#include "mgsr/io/scene.h"

namespace mgsr {

struct BackdropOptions {
  // Width of the border ring sampled in each training photo, as a fraction of its shorter side.
  double border_fraction = 1.0 / 32;
  // Uniform means: 80% of the border samples lie within `max_spread` of the per-channel medians
  // (objects may touch the border), and the medians differ by at most `max_tint` (grey).
  double max_spread = 0.03, max_tint = 0.03;
};

struct Backdrop {
  bool uniform = false;  // true: `level` is the backdrop's grey
  float level = 0;
  float spread = 0;    // the 80th percentile of |sample - median|
  std::string reason;  // why not uniform, for the user
};

// Looks at the training photos only. Photos with a mask or alpha have no backdrop to estimate.
Backdrop EstimateBackdrop(const Scene& scene, const BackdropOptions& options = {});

}  // namespace mgsr
