// Rasterization stage of the 3DGS branch with MGSR's reflection decomposition (method.md 2.2):
// per 16x16 tile, front-to-back alpha blending of the depth-sorted Gaussians, two transmittance
// chains per pixel:
//   C_tran = sum_i c_t,i a_i T_i + T_N bg        (a_i = min(0.99, o_i G_i),
//                                                 T_i = prod_{j<i} (1 - a_j))
//   C_ref  = sum_i c_r,i ar_i Tr_i               (ar_i = min(0.99, or_i G_i), own chain,
//                                                 no background)
//   W      = sum_i beta_i a_i T_i                (beta blended with the transmitted weights)
//   D      = sum_i z_i a_i T_i / A, A = 1 - T_N  (0 where A < kMinDepthAlpha)
//   C      = C_tran + W * C_ref
// A Gaussian affects a pixel only inside its 3-sigma square (|dx|, |dy| <= radius), where the
// exponent is <= 0, and in a chain only if that chain's alpha >= 1/255 (each chain decides for
// itself: a departure from the authors' kernels, which skip both when either alpha is small,
// method.md 2.2). A chain stops when its transmittance would fall below 1e-4 (that Gaussian
// is not blended in it); the pixel stops when every chain has. Tiles and pixel loops visit only
// the box where some alpha can reach 1/255 (ProjectedGaussians::extent), which changes nothing.
#pragma once

#include <cstdint>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/render/project_gaussians.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr {

// The pixel loops' per-thread scratch (raster_scratch.h, internal: instruction-set dependent).
struct RasterScratch;

constexpr float kMinAlpha = kMinBlendAlpha;
constexpr float kMaxAlpha = 0.99f;
constexpr float kMinTransmittance = 1e-4f;
constexpr float kMinDepthAlpha = 1e-4f;

struct GaussianRenderOptions {
  Camera camera;
  int sh_degree = 3;
  bool reflection = true;  // false: plain 3DGS (C = C_tran; C_ref and W are zero)
  float background[3] = {0, 0, 0};
  // When set (3 channels, the camera's size): a background per pixel instead of `background`, e.g.
  // a learnt environment (solvers/environment_background.h). Not owned.
  const Image* background_image = nullptr;
  // Also sum each Gaussian's blend weights over the image (GaussianRender::contribution): what
  // pruning by contribution reads. Off in training steps (it costs a reduction per row).
  bool record_contribution = false;
};

struct GaussianRender {
  Image color, tran, ref;      // 3 channels
  Image weight, depth, alpha;  // 1 channel: W, D, A
  // Kept for the backward pass.
  std::vector<float> final_t, final_tr, depth_sum;
  std::vector<uint32_t> last_t,
      last_r;  // per pixel: 1 + index (within its tile list) of the last blended
  // With options.record_contribution, per Gaussian: the sum over pixels of its blend weights in
  // the transmitted chain plus those in the reflected chain (else empty).
  std::vector<float> contribution;
  // Per tile entry of the bins rendered: 1 where the Gaussian blended a pixel of that tile (either
  // chain), else 0. The backward skips the others, whose gradients are zero: a pixel takes part
  // in the backward exactly where it blended in the forward.
  std::vector<uint8_t> entry_blended;
};

// Upstream gradients; an empty image means zero.
struct GaussianRenderGrad {
  Image color, tran, ref, weight, depth, alpha;
};

void RasterizeGaussians(const ProjectedGaussians& projected, const TileBins& bins,
                        const GaussianRenderOptions& options, GaussianRender* out,
                        RasterScratch* scratch);

// d loss / d (the background of each pixel), 3 channels: the transmitted colour and the colour
// both hold T_N * background, so it is T_N * (gradient of colour + gradient of tran).
void GaussianBackgroundGradient(const GaussianRender& render, const GaussianRenderGrad& grad,
                                Image* d_background);

// Writes d loss / d projected quantities into `d_projected` (sized here; every entry written, so
// no zero-fill before: 6 MB for 100k Gaussians).
void RasterizeGaussiansBackward(const ProjectedGaussians& projected, const TileBins& bins,
                                const GaussianRenderOptions& options, const GaussianRender& render,
                                const GaussianRenderGrad& grad, ProjectedGaussiansGrad* d_projected,
                                RasterScratch* scratch);

}  // namespace mgsr
