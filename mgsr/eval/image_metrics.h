// Image quality: PSNR and SSIM as the reference evaluates them (method.md 6.1, 1.14):
//   PSNR = 10 log10(1 / MSE) over all pixels and channels (images in [0, 1]);
//   SSIM = mean over pixels and channels of the SSIM map with an 11x11 Gaussian window (sigma 1.5),
//          zero padding, C1 = 0.01^2, C2 = 0.03^2, each channel on its own.
#pragma once

#include <vector>

#include "mgsr/core/image.h"

namespace mgsr {

// Both images must have the same shape. Identical images give +infinity.
double Psnr(const Image& a, const Image& b);
// PSNR over the pixels where `mask` (one channel, a's size) is at least 0.5: the object alone,
// whatever the framing puts around it. NaN when the mask selects nothing.
double ForegroundPsnr(const Image& a, const Image& b, const Image& mask);
double Ssim(const Image& a, const Image& b);

// The normalised 1-D Gaussian window used by SSIM (size 11, sigma 1.5).
std::vector<float> SsimWindow();

// Separable blur of one plane with `kernel` (odd length), zero padding outside the image.
void BlurZeroPadded(const float* in, int width, int height, const std::vector<float>& kernel,
                    float* out, std::vector<float>* scratch);

}  // namespace mgsr
