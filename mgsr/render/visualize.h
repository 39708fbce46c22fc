// Pictures of geometry buffers a person can read: depth through a perceptual colour map over a
// range that fits the object, normals as colours, both black where nothing was rendered.
#pragma once

#include "mgsr/core/image.h"

namespace mgsr {

struct DepthRange {
  float near = 0, far = 0;  // far <= near: empty (nothing rendered)
};

// The 2nd to 98th percentile of the depth where alpha >= 0.5, widened by 2% of its span at each
// end so the object's own depth fills the colour map (a stray far splat does not squash it).
DepthRange RenderedDepthRange(const Image& depth, const Image& alpha);

// Depth -> RGB through a turbo-like map (near: red, far: blue); black where alpha < 0.5.
// Values outside the range are clamped to its ends.
Image DepthColormap(const Image& depth, const Image& alpha, const DepthRange& range);

// Unit normals (3 channels, any frame) -> RGB 0.5 + 0.5 n; black where alpha < 0.5.
Image NormalColormap(const Image& normal, const Image& alpha);

}  // namespace mgsr
