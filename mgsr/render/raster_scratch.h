// Per-thread scratch memory shared by the tile rasterizers, reused between calls so that a warm
// renderer does not allocate.
#pragma once

#include <vector>

namespace mgsr {

// Per-thread scratch of the rasterizer (reused between calls).
struct RasterScratch {
  std::vector<float> packed;                    // per primitive: the fields the pixel loops read
  std::vector<std::vector<float>> pixel_state;  // per thread: pixel state of the current tile
  std::vector<std::vector<float>> tile_data;  // per thread: gathered Gaussians of the current tile
  std::vector<std::vector<float>> tile_grad;  // per thread: gradients of the current tile
  std::vector<std::vector<float>> grads;      // per thread: N x kGradStride accumulators
};

}  // namespace mgsr
