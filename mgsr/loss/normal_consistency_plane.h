// The pixel loop of NormalConsistencyLoss (mgsr/loss/normal_consistency_loss.h): the
// depth-normal consistency of every pixel and its gradient in the rendered normals and the depth.
//
// Vectorised over a row's pixels (structure of arrays: depth, three normal planes, alpha, mask,
// three ray planes), compiled for the host CPU like the D-SSIM kernel, but without fused
// multiply-adds (-ffp-contract=off): every pixel's arithmetic is the operations, in the order,
// of the scalar loop it replaces (Eigen's 3-vector sums are x + (y + z)), so values and gradients
// are the same to the bit on any instruction set. Rows are threaded in three interleaved phases
// (a pixel writes the depth gradient of the rows above and below it); within a row the depth
// gradient at x takes its left neighbour's share before its right neighbour's, as the scalar loop
// did; per-row sums are added in row order.
#pragma once

namespace mgsr {

// One-sided differences: an axis is taken one-sided where one neighbour's depth jump from the
// centre exceeds the other's by this factor (docs/geometry.md, "Steps in the depth").
constexpr float kNormalStepRatio = 3.0f;

// The planes of one evaluation (w x h, row-major; each normal or ray plane is w x h).
template <typename T>
struct NormalConsistencyPlanes {
  int width = 0, height = 0;
  const T* depth = nullptr;
  const T* normal[3] = {nullptr, nullptr, nullptr};  // rendered world normal (alpha-weighted)
  const T* alpha = nullptr;                          // held constant
  const T* mask = nullptr;                           // foreground weight gamma; null: 1
  const T* ray[3] = {nullptr, nullptr, nullptr};     // world ray of each pixel (camera z = 1)
  T center[3] = {0, 0, 0};                           // camera centre
  // sigma > 0: each pixel's residual r = 1 - <N_rend, alpha N_surf> enters as sigma r / (r + sigma)
  // (linear near 0, bounded by sigma); 0: as r.
  T robust_scale = 0;
  // true: along an axis whose two neighbours' depth jumps from the centre differ by more than
  // kNormalStepRatio, N_surf takes the one-sided difference towards the closer neighbour (central
  // elsewhere); false: central differences everywhere.
  bool one_sided = false;
  // When not null, gradients are added here: `gain` x d(sum of the per-pixel terms)/d input.
  T* d_normal[3] = {nullptr, nullptr, nullptr};
  T* d_depth = nullptr;
  T gain = 0;
};

// Returns the sum over pixels of gamma rho(1 - <N_rend, alpha N_surf>), rho the identity or the
// bounded function of `robust_scale` (the mean is the caller's).
double NormalConsistencySum(const NormalConsistencyPlanes<float>& p);
double NormalConsistencySum(const NormalConsistencyPlanes<double>& p);

}  // namespace mgsr
