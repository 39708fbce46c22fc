// Projection stage of the 3DGS branch (method.md 4.1): per Gaussian, the view-space mean, the EWA
// screen covariance with the 0.3 px^2 dilation and the 1.3 x fov clamp of the Jacobian, its conic,
// a 3-sigma radius, the screen box that can receive alpha >= 1/255 and its tile rectangle,
// activated opacities and the SH colours (transmitted and, for MGSR, reflected). Pixel coordinates
// follow COLMAP: pixel (x, y) spans [x, x+1) x [y, y+1), so its centre is (x + 0.5, y + 0.5).
#pragma once

#include <cstdint>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/model/gaussian_model.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr {

constexpr float kNearPlane = 0.2f;
constexpr float kScreenDilation = 0.3f;  // px^2 added to the screen covariance (low-pass)
constexpr float kFovClamp = 1.3f;

constexpr float kMinBlendAlpha = 1.0f / 255.0f;  // alpha below this is not blended

// Half-widths (ex, ey) of the screen box outside which a Gaussian of screen covariance diagonal
// (cov_xx, cov_yy) and peak opacity `opacity` stays below kMinBlendAlpha, capped at `radius`;
// false (and no box) when even its peak does.
bool AlphaExtent(float cov_xx, float cov_yy, float opacity, float radius, float* ex, float* ey);

struct ProjectedGaussians {
  std::vector<float> mean2d;  // N x 2, pixels
  std::vector<float> conic;   // N x 3 (a, b, c): power = -a dx^2 / 2 - b dx dy - c dy^2 / 2
  std::vector<float> depth;   // N, view-space z
  std::vector<float> radius;  // N, pixels; 0 = culled
  // N x 2, pixels: half-widths of the box around the mean outside which the Gaussian's alpha
  // (and, with reflection, its reflected alpha) stays below 1/255; at most the radius. The tile
  // rectangle and the rasterizers' row and column ranges come from it.
  std::vector<float> extent;
  // N: the exponent (power) below which neither alpha reaches 1/255, ln(1/255 / o) with o the
  // larger of the two opacities (the transmitted one without reflection); 0 where not binned.
  std::vector<float> min_power;
  std::vector<TileRect> rects;
  // N: the ellipse within the rectangle where the pixel loops' exponent test can pass (binning
  // leaves out the rectangle's tiles it misses). Set only where the rectangle is at least
  // kMinEllipseBinningWidth tiles wide, the only ones binning reads.
  std::vector<TileEllipse> shapes;
  std::vector<float> opacity, ref_opacity, beta;  // N, activated
  std::vector<float> color_t, color_r;            // N x 3
  std::vector<uint8_t> clamp_t, clamp_r;          // N x 3
  std::vector<float> view_dir;                    // N x 3, unit (mean - camera centre)

  size_t size() const { return depth.size(); }
  void Resize(size_t n);
};

// Gradients of the loss with respect to the projected quantities (filled by the rasterizer).
struct ProjectedGaussiansGrad {
  std::vector<float> mean2d, conic, depth, opacity, ref_opacity, beta, color_t, color_r;
  void ResizeAndZero(size_t n);
  void Resize(size_t n);  // sized, not zeroed
};

// `reflection` false: the reflected quantities are not computed (plain 3DGS).
void ProjectGaussians(const GaussianModel& model, const Camera& camera, int sh_degree,
                      bool reflection, ProjectedGaussians* out);

// Gradients of the model's raw parameters (same layout as the model) plus the per-Gaussian
// screen-space mean gradient (pixels) that density control accumulates.
struct GaussianGradients {
  GaussianModel params;       // d loss / d raw parameter, model layout
  std::vector<float> mean2d;  // N x 2

  void ResizeAndZero(const GaussianModel& model);
  // Only sized: ProjectGaussiansBackward writes every entry (no 10 MB zero-fill per 100k step).
  void ResizeForBackward(const GaussianModel& model);
};

// |d loss / d screen mean| per Gaussian in NDC units (the pixel gradient times W/2 and H/2), the
// statistic density control compares with its threshold (method.md 1.10: 2e-4).
// (For the 2DGS branch pass its reference-3.8(5) statistic, SurfelGradients::mean2d.)
void ScreenGradientNorms(const std::vector<float>& mean2d_grads, int width, int height,
                         std::vector<float>* norms);

// Writes the chain from projected-quantity gradients to every raw parameter into `grads` (sized
// by GaussianGradients::ResizeForBackward; every entry, zero for Gaussians not drawn).
void ProjectGaussiansBackward(const GaussianModel& model, const Camera& camera, int sh_degree,
                              bool reflection, const ProjectedGaussians& projected,
                              const ProjectedGaussiansGrad& d_projected, GaussianGradients* grads);

}  // namespace mgsr
