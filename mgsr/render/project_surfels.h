// Projection stage of the 2DGS branch (method.md 3.1-3.2), in COLMAP pixel coordinates (pixel
// (x, y) spans [x, x+1) x [y, y+1)). A surfel is the disk X(u, v) = p + s_u u t_u + s_v v t_v;
// through the camera it becomes the 3x3 matrix M = K [R_c [s_u t_u, s_v t_v, p] + t_c e3^T] whose
// rows T_u, T_v, T_w give x_num, y_num and depth of the local point (u, v, 1). Per surfel: M, the
// camera-facing view-space normal, the screen centre m and radius of the projected 3-sigma disk
// (with the low-pass floor), opacity and SH colour.
#pragma once

#include <cstdint>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/model/surfel_model.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr {

constexpr float kSurfelNear = 0.2f, kSurfelFar = 100.0f;
// (3 sigma)^2: the disk's extent in its local (u, v) units that the screen radius covers.
constexpr float kSurfelCutoff2 = 9.0f;
// The reference's screen low-pass: a Gaussian of sigma sqrt(2)/2 px (rho2d = 2 |d|^2).
constexpr float kReferenceSurfelFilterSigma = 0.70710678f;

struct ProjectedSurfels {
  // N x 9: rows T_u - m_x T_w, T_v - m_y T_w, T_w. Centring on the screen centre m keeps the
  // per-pixel intersection (k = (x - m_x) T_w - T_u', ...) free of float cancellation; the rows are
  // computed in double.
  std::vector<float> M;
  std::vector<float> center;  // N x 2: screen centre m (pixels)
  std::vector<float> radius;  // N, pixels; 0 = culled
  std::vector<TileRect> rects;
  std::vector<float> depth;        // N: view depth of p (sort key)
  std::vector<float> normal;       // N x 3: view-space unit normal facing the camera
  std::vector<float> normal_sign;  // N: +1 or -1 (flipped to face the camera)
  std::vector<float> opacity;      // N
  std::vector<float> color;        // N x 3
  std::vector<uint8_t> clamp;      // N x 3
  std::vector<float> view_dir;     // N x 3
  // What the pixel loops need that no tile changes: the exponent below which alpha < 1/255 (0 when
  // the opacity is below it), and the half-extents around m beyond which no pixel reaches 1/255,
  // whose box gives `rects`; `radius` (the 3-sigma square, what "visible" means) is at least as
  // wide.
  std::vector<float> min_power;  // N
  std::vector<float> extent;     // N x 2
  // N x 2: the ellipses within the rectangle where the pixel loops' test can pass, the image of
  // the disk and the low-pass circle (binning leaves out the rectangle's tiles both miss). Set
  // only where the rectangle is at least kMinEllipseBinningWidth tiles wide, the only ones
  // binning reads.
  std::vector<TileEllipse> shapes;

  size_t size() const { return depth.size(); }
  void Resize(size_t n);
};

struct ProjectedSurfelsGrad {
  std::vector<float> M, center, normal, opacity, color;
  void ResizeAndZero(size_t n);
  void Resize(size_t n);  // sized, not zeroed
};

struct SurfelGradients {
  SurfelModel params;         // d loss / d raw parameter, model layout
  std::vector<float> mean2d;  // N x 2: the densification statistic of method.md 3.8, pixels
  void ResizeAndZero(const SurfelModel& model);
  // Only sized: ProjectSurfelsBackward writes every entry.
  void ResizeForBackward(const SurfelModel& model);
};

// filter_sigma: the screen low-pass's sigma in pixels; the screen radius is at least 3 of them.
void ProjectSurfels(const SurfelModel& model, const Camera& camera, int sh_degree,
                    ProjectedSurfels* out, float filter_sigma = kReferenceSurfelFilterSigma);

// Writes the chain from projected-quantity gradients to every raw parameter into `grads` (sized
// by SurfelGradients::ResizeForBackward; every entry, zero for surfels not drawn).
void ProjectSurfelsBackward(const SurfelModel& model, const Camera& camera, int sh_degree,
                            const ProjectedSurfels& projected,
                            const ProjectedSurfelsGrad& d_projected, SurfelGradients* grads);

}  // namespace mgsr
