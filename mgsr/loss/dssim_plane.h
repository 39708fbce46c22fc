// The SSIM of one image plane against another and its gradient, the kernel behind DssimLoss: an
// 11x11 Gaussian window (sigma 1.5), zero padding, C1 = 0.01^2, C2 = 0.03^2 (method.md 1.14).
//
// One fused pass per plane instead of eight separate blurs: each thread walks a band of rows,
// and per row takes the horizontal blurs of the five moments from one read of the row, then (five
// rows behind) the vertical blur, the SSIM map and the horizontal blur of its three partials, then
// (five more rows behind) the gradient row. The blurred rows live in rings of 11 rows per plane,
// so they stay in cache at photo size; a band recomputes the 10 rows of its edges. Per-row sums
// are added in row order, so values and gradients do not depend on the thread count. Compiled for
// the host CPU like the rasterizers (a separate translation unit, so no inline code is built for
// two instruction sets). Scratch memory is kept per thread between calls: no allocation once the
// size has been seen.
#pragma once

namespace mgsr {

// Returns the sum of the SSIM map of x against y (w x h, row-major). When `grad` is not null, adds
// `scale` x d(sum of the map)/dx to it.
double SsimPlaneSum(const float* x, const float* y, int width, int height, float scale,
                    float* grad);
double SsimPlaneSum(const double* x, const double* y, int width, int height, double scale,
                    double* grad);

}  // namespace mgsr
