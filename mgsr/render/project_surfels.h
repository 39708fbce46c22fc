// Projection stage of the 2DGS branch (reference 3.1-3.2), in COLMAP pixel coordinates (pixel
// (x, y) spans [x, x+1) x [y, y+1)). A surfel is the disk X(u, v) = p + s_u u t_u + s_v v t_v;
// through the camera it becomes the 3x3 matrix M = K [R_c [s_u t_u, s_v t_v, p] + t_c e3^T] whose
// rows T_u, T_v, T_w give x_num, y_num and depth of the local point (u, v, 1). Per surfel: M, the
// camera-facing view-space normal, the screen centre m and radius of the projected 3-sigma disk
// (with the low-pass floor), opacity and SH colour.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/model/surfel_model.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr {

constexpr float kSurfelNear = 0.2f, kSurfelFar = 100.0f;
// The reference's screen low-pass: a Gaussian of sigma sqrt(2)/2 px (rho2d = 2 |d|^2).
constexpr float kReferenceSurfelFilterSigma = 0.70710678f;

enum class SurfelLowPass {
  kReference,       // 2DGS: the filter at the surfel's full opacity
  kAreaPreserving,  // the filter's opacity scaled by the surfel's projected area (no dilation)
};

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
  // What the pixel loops need that no tile changes: the low-pass offset c added to rho2d (see
  // rasterize_surfels.h), the exponent below which alpha < 1/255 (0 when the opacity is below it),
  // and the half-extents around m beyond which no pixel reaches 1/255 (SurfelAlphaReach), whose
  // box gives `rects`; `radius` (the 3-sigma square, what "visible" means) is at least as wide.
  std::vector<float> low_pass, min_power;  // N
  std::vector<float> extent;               // N x 2

  size_t size() const { return depth.size(); }
  void Resize(size_t n);
};

struct ProjectedSurfelsGrad {
  std::vector<float> M, center, normal, opacity, color;
  void ResizeAndZero(size_t n);
};

struct SurfelGradients {
  SurfelModel params;         // d loss / d raw parameter, model layout
  std::vector<float> mean2d;  // N x 2: the densification statistic of reference 3.8(5), pixels
  void ResizeAndZero(const SurfelModel& model);
};

// filter_sigma: the screen low-pass's sigma in pixels; the screen radius is at least 3 of them.
void ProjectSurfels(const SurfelModel& model, const Camera& camera, int sh_degree,
                    ProjectedSurfels* out, float filter_sigma = kReferenceSurfelFilterSigma,
                    SurfelLowPass low_pass = SurfelLowPass::kReference);

// The area-preserving low-pass floor's offset c of rho2d (see rasterize_surfels.h) from the stored
// rows tu, tv, tw of ProjectedSurfels::M: e^{-c/2} = min(1, |det J| / s^2) with det J = det M /
// T_w2^3 and s the filter's sigma (inv_square = 1 / s^2). `dc` (may be null) receives d c / d M
// (row-major over the stored rows, which differ from M by row operations that keep its
// determinant) where c > 0 and not capped.
constexpr float kMinFilterArea = 1e-6f;  // below: the filter adds nothing visible (c is capped)
inline float SurfelLowPassOffset(const float tu[3], const float tv[3], const float tw[3],
                                 float inv_square, float dc[9]) {
  const float cof[9] = {
      tv[1] * tw[2] - tv[2] * tw[1], tv[2] * tw[0] - tv[0] * tw[2], tv[0] * tw[1] - tv[1] * tw[0],
      tw[1] * tu[2] - tw[2] * tu[1], tw[2] * tu[0] - tw[0] * tu[2], tw[0] * tu[1] - tw[1] * tu[0],
      tu[1] * tv[2] - tu[2] * tv[1], tu[2] * tv[0] - tu[0] * tv[2], tu[0] * tv[1] - tu[1] * tv[0]};
  const float det = tu[0] * cof[0] + tu[1] * cof[1] + tu[2] * cof[2];
  const float z = tw[2];
  const float area = inv_square * std::abs(det) / (z * z * z);
  if (dc != nullptr) std::fill(dc, dc + 9, 0.0f);
  if (!(area < 1.0f)) return 0.0f;
  if (!(area > kMinFilterArea)) return -2.0f * std::log(kMinFilterArea);
  if (dc != nullptr) {
    // c = -2 ln|det| + 6 ln z + const; d ln|det| / d M = cof / det.
    for (int q = 0; q < 9; ++q) dc[q] = -2.0f * cof[q] / det;
    dc[8] += 6.0f / z;
  }
  return -2.0f * std::log(area);
}

// The half-extents (ex, ey) around the centre beyond which no pixel of a surfel reaches alpha
// 1/255, i.e. rho = min(rho3d, rho2d) <= r2 = -2 min_power: the bounding box of the image of the
// disk u^2 + v^2 <= r2 (a conic; the box as for the 3-sigma one, from the stored rows) and of the
// low-pass circle |pixel - m|^2 <= (r2 - c) sigma^2, widened by 2% and half a pixel against float
// rounding in the pixel loops, and at most `radius`.
void SurfelAlphaReach(const float tu[3], const float tv[3], const float tw[3], float radius,
                      float low_pass, float inv_square, float min_power, float* ex, float* ey);

void ProjectSurfelsBackward(const SurfelModel& model, const Camera& camera, int sh_degree,
                            const ProjectedSurfels& projected,
                            const ProjectedSurfelsGrad& d_projected, SurfelGradients* grads);

}  // namespace mgsr
