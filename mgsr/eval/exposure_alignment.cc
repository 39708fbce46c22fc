#include "mgsr/eval/exposure_alignment.h"

#include <Eigen/Dense>

#include "mgsr/eval/image_metrics.h"

namespace mgsr {

Eigen::Matrix<double, 3, 4> FitAffineColor(const Image& render, const Image& target,
                                           const Image* mask) {
  Eigen::Matrix<double, 3, 4> M = Eigen::Matrix<double, 3, 4>::Zero();
  M.leftCols<3>().setIdentity();
  // Normal equations over the pixels: [r 1]^T [r 1] x = [r 1]^T t, one 4x4 system for all channels.
  Eigen::Matrix4d AtA = Eigen::Matrix4d::Zero();
  Eigen::Matrix<double, 4, 3> AtB = Eigen::Matrix<double, 4, 3>::Zero();
  size_t used = 0;
  for (size_t i = 0; i < render.plane_size(); ++i) {
    if (mask != nullptr && mask->plane(0)[i] < 0.5f) continue;
    const Eigen::Vector4d r(render.plane(0)[i], render.plane(1)[i], render.plane(2)[i], 1.0);
    const Eigen::Vector3d t(target.plane(0)[i], target.plane(1)[i], target.plane(2)[i]);
    AtA += r * r.transpose();
    AtB += r * t.transpose();
    ++used;
  }
  if (used < 16) return M;
  // A tiny ridge keeps flat-coloured images (rank-deficient) solvable.
  AtA += 1e-9 * static_cast<double>(used) * Eigen::Matrix4d::Identity();
  const Eigen::Matrix<double, 4, 3> X = AtA.ldlt().solve(AtB);
  if (!X.allFinite()) return M;
  return X.transpose();
}

Image ApplyAffineColor(const Image& render, const Eigen::Matrix<double, 3, 4>& M,
                       const Image* mask) {
  Image out = render;
  for (size_t i = 0; i < render.plane_size(); ++i) {
    if (mask != nullptr && mask->plane(0)[i] < 0.5f) continue;
    const Eigen::Vector4d r(render.plane(0)[i], render.plane(1)[i], render.plane(2)[i], 1.0);
    const Eigen::Vector3d t = M * r;
    for (int c = 0; c < 3; ++c) out.plane(c)[i] = static_cast<float>(t[c]);
  }
  return out;
}

AlignedScores ExposureAlignedScores(const Image& render, const Image& target, const Image* mask) {
  AlignedScores s;
  s.transform = FitAffineColor(render, target, mask);
  const Image aligned = ApplyAffineColor(render, s.transform, mask);
  s.psnr = Psnr(aligned, target);
  s.ssim = Ssim(aligned, target);
  return s;
}

}  // namespace mgsr
