// Rasterization stage of the 2DGS branch (method.md 3.3-3.4): per tile, front-to-back blending of
// depth-sorted surfels with the exact ray-splat intersection in each splat's (u, v) frame:
//   k = x T_w - T_u, l = y T_w - T_v, p = k x l, (u, v) = (p_x, p_y) / p_z   at the pixel centre
//   (x, y) rho = min(u^2 + v^2, 2 |m - (x, y)|^2 + c)   (the screen low-pass floor), G = exp(-rho /
//   2) z = T_w . (u, v, 1)  (skipped below the near plane), a = min(0.99, o G)
// Outputs per pixel: C = sum w c + T_N bg, expected depth D = sum w z / A (0 where A < 1e-4),
// A = 1 - T_N, N = sum w n (view space; world = R_c^T N), the median depth (z of the last surfel
// blended while T > 0.5) and the depth distortion sum_i sum_{j<i} w_i w_j (m_i - m_j)^2 of NDC
// depths m = far/(far-near) (1 - near/z). A surfel affects a pixel only inside its square
// |x - m_x|, |y - m_y| <= radius and only where a >= 1/255; a pixel stops when T would fall below
// 1e-4 (that surfel is not blended).
// The low-pass floor keeps sub-pixel and edge-on surfels visible. The reference (2DGS, the
// default) gives it the surfel's full opacity (c = 0): a surfel far thinner than a pixel then
// covers a disk of sigma 0.7 px, so a cover of small edge-on surfels draws its silhouette 1-2 px
// too wide. The area-preserving floor scales the filter's opacity by the surfel's screen area over
// the filter's,
//   e^{-c/2} = min(1, 2 |det J|),  det J = det M / T_w2^3  (the screen Jacobian at the centre),
// so a surfel adds coverage in proportion to the area it projects to, as in Mip-Splatting. It
// renders a given surface's silhouette exactly, but trained on the synthetic scenes its surfaces
// sat deeper inside the truth than the reference's (docs/geometry.md), so it is an option.
#pragma once

#include <cstdint>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/render/project_surfels.h"
#include "mgsr/render/rasterize_gaussians.h"  // shared constants (alpha clamps, termination)
#include "mgsr/render/tile_binning.h"

namespace mgsr {

// The pixel loops' per-thread scratch (raster_scratch.h, internal: instruction-set dependent).
struct RasterScratch;

enum class SurfelLowPass {
  kReference,       // 2DGS: the filter at the surfel's full opacity
  kAreaPreserving,  // the filter's opacity scaled by the surfel's projected area (no dilation)
};

struct SurfelRenderOptions {
  Camera camera;
  int sh_degree = 3;
  float background[3] = {0, 0, 0};
  // When set (3 channels, the camera's size): a background per pixel instead of `background`.
  // Not owned.
  const Image* background_image = nullptr;
  SurfelLowPass low_pass = SurfelLowPass::kReference;
  // The screen low-pass Gaussian's sigma in pixels (rho2d = |m - pixel|^2 / sigma^2). Smaller
  // dilates silhouettes less: every footprint is at least this wide, so an edge-on disk at a
  // silhouette draws the object's outline about a sigma too far out, and the fit pulls the surface
  // in to compensate (docs/geometry.md).
  float filter_sigma = kReferenceSurfelFilterSigma;
  // Also sum each surfel's blend weights over the image (SurfelRender::contribution): what pruning
  // by contribution reads. Off in training steps (it costs a reduction per row).
  bool record_contribution = false;
  // Also the depth distortion (SurfelRender::distortion and its backward state). Off, its image
  // and state stay empty, the pass skips its sums (a division and eight tile-state loads and
  // stores per blended row), and the backward ignores a distortion gradient. Training turns it off
  // when no active loss row reads the buffer (the reference never uses it).
  bool distortion = true;
};

struct SurfelRender {
  Image color;  // 3 channels
  Image depth;  // expected depth
  Image alpha;
  Image normal;        // view space, alpha-weighted (not normalised)
  Image normal_world;  // R_c^T normal
  Image median_depth;
  Image distortion;
  // Kept for the backward pass.
  // weight_sum = sum of the blend weights = 1 - final_t, but without the cancellation of 1 - T
  // where the alpha is small: the expected depth is depth_sum / weight_sum.
  std::vector<float> final_t, depth_sum, weight_sum, m1, m2, m_ref;  // m1, m2: see .cc
  std::vector<uint32_t> last, median_index;  // 1 + index within the tile list (0: none)
  // With options.record_contribution, per surfel: the sum over pixels of its blend weights (else
  // empty).
  std::vector<float> contribution;
  // Per tile entry of the bins rendered: 1 where the surfel blended a pixel of that tile, else 0.
  // The backward skips the others, whose gradients are zero: a pixel takes part in the backward
  // exactly where it blended in the forward.
  std::vector<uint8_t> entry_blended;
};

// Upstream gradients; an empty image means zero.
struct SurfelRenderGrad {
  Image color, depth, alpha, normal, normal_world, median_depth, distortion;
};

void RasterizeSurfels(const ProjectedSurfels& projected, const TileBins& bins,
                      const SurfelRenderOptions& options, SurfelRender* out,
                      RasterScratch* scratch);

// d loss / d (the background of each pixel), 3 channels: T_N * (gradient of colour).
void SurfelBackgroundGradient(const SurfelRender& render, const SurfelRenderGrad& grad,
                              Image* d_background);

// Writes d loss / d projected quantities into `d_projected` (sized here; every entry written).
void RasterizeSurfelsBackward(const ProjectedSurfels& projected, const TileBins& bins,
                              const SurfelRenderOptions& options, const SurfelRender& render,
                              const SurfelRenderGrad& grad, ProjectedSurfelsGrad* d_projected,
                              RasterScratch* scratch);

}  // namespace mgsr
