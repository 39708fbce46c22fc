// Exposure-aligned image scores, as in-the-wild novel-view benchmarks report them: per test image,
// fit the affine colour transform target ~ A render + b (3x3 gain and 3 offsets) by least squares,
// over the mask when one is given, then score the transformed render. This separates exposure and
// white-balance differences (which no model of the scene can predict for an unseen view) from
// reconstruction error.
#pragma once

#include <Eigen/Core>

#include "mgsr/core/image.h"

namespace mgsr {

// M = [A | b] (3 x 4). Falls back to the identity when there are too few pixels to fit.
Eigen::Matrix<double, 3, 4> FitAffineColor(const Image& render, const Image& target,
                                           const Image* mask = nullptr);
// Applies M to every pixel, or only inside the mask when one is given (the background keeps the
// render's values, which already match a uniform background).
Image ApplyAffineColor(const Image& render, const Eigen::Matrix<double, 3, 4>& M,
                       const Image* mask = nullptr);

struct AlignedScores {
  double psnr = 0, ssim = 0;
  Eigen::Matrix<double, 3, 4> transform;
};
AlignedScores ExposureAlignedScores(const Image& render, const Image& target,
                                    const Image* mask = nullptr);

}  // namespace mgsr
