// The kernel behind EdgeAwareTvLoss (mgsr/loss/edge_aware_tv_loss.h): the edge weights of a guide
// image and the weighted squared differences of a buffer between neighbouring pixels, with their
// gradient. Rows are independent (each pixel gathers its gradient from its own differences and
// those of its upper and left neighbours), split across threads and vectorised; per-row sums are
// added in row order, so nothing depends on the thread count. Compiled for the host CPU (its own
// translation unit, like the rasterizers); the float path takes the rasterizers' polynomial exp
// (relative error ~1e-7), the double path std::exp. Scratch is kept per thread between calls.
#pragma once

namespace mgsr {

// P: `channels` planes of width x height; I: `guide_channels` planes of the same size. Sets
// *vertical = sum_{c, y < H-1, x} w_v (P(y+1,x) - P(y,x))^2 and *horizontal likewise along x,
// with w = exp(-mean over the guide's channels of |I difference|), times gamma(a) gamma(b) of the
// pair's two pixels when `gamma` (one plane, held constant) is not null. When `grad` is not null,
// adds scale_v x d(*vertical)/dP + scale_h x d(*horizontal)/dP to it.
void EdgeAwareTvSums(const float* P, int channels, const float* I, int guide_channels,
                     const float* gamma, int width, int height, float scale_v, float scale_h,
                     float* grad, double* vertical, double* horizontal);
void EdgeAwareTvSums(const double* P, int channels, const double* I, int guide_channels,
                     const double* gamma, int width, int height, double scale_v, double scale_h,
                     double* grad, double* vertical, double* horizontal);

}  // namespace mgsr
