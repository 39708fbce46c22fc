#include "mgsr/eval/pose_alignment.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace mgsr {

Status ComparePoses(const std::vector<Camera>& estimate, const std::vector<Camera>& truth,
                    PoseErrors* errors) {
  *errors = PoseErrors();
  if (estimate.size() != truth.size())
    return Status::Error("ComparePoses: " + std::to_string(estimate.size()) + " estimated vs " +
                         std::to_string(truth.size()) + " true poses");
  const int n = static_cast<int>(estimate.size());
  if (n < 3) return Status::Error("ComparePoses: at least 3 poses are needed");
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (int i = 0; i < n; ++i) {
    src.col(i) = estimate[i].Center();
    dst.col(i) = truth[i].Center();
  }
  const Eigen::Vector3d centroid = dst.rowwise().mean();
  double extent = 0;
  for (int i = 0; i < n; ++i) extent = std::max(extent, (dst.col(i) - centroid).norm());
  // Collinear (or coincident) centres leave the rotation about their line undetermined.
  Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(src.colwise() - src.rowwise().mean());
  if (extent <= 0 || svd.singularValues()(1) <= 1e-9 * svd.singularValues()(0))
    return Status::Error("ComparePoses: camera centres are collinear; no unique alignment");

  const Eigen::Matrix4d sim = Eigen::umeyama(src, dst, /*with_scaling=*/true);
  const Eigen::Matrix3d sR = sim.topLeftCorner<3, 3>();
  errors->scale = std::cbrt(sR.determinant());
  const Eigen::Matrix3d align_R = sR / errors->scale;
  const Eigen::Vector3d align_t = sim.topRightCorner<3, 1>();
  errors->num_poses = n;
  for (int i = 0; i < n; ++i) {
    // x_true = s A x_est + b, so the aligned world->camera rotation is R_est A^T.
    const Eigen::Matrix3d R_aligned = estimate[i].R * align_R.transpose();
    const double cos_angle =
        std::clamp(((R_aligned * truth[i].R.transpose()).trace() - 1.0) / 2.0, -1.0, 1.0);
    const double rot_deg = std::acos(cos_angle) * 180.0 / M_PI;
    const Eigen::Vector3d c = errors->scale * align_R * src.col(i) + align_t;
    const double trans = (c - dst.col(i)).norm() / extent;
    errors->rotation_deg.push_back(rot_deg);
    errors->translation_rel.push_back(trans);
    errors->mean_rotation_deg += rot_deg / n;
    errors->max_rotation_deg = std::max(errors->max_rotation_deg, rot_deg);
    errors->mean_translation_rel += trans / n;
    errors->max_translation_rel = std::max(errors->max_translation_rel, trans);
  }
  return Status::Ok();
}

}  // namespace mgsr
