#include "mgsr/eval/pose_alignment.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace mgsr {
namespace {

// Whether the points lie on one line (or coincide), which leaves the rotation about that line
// undetermined: the farthest point from their centroid gives the line's direction, and no point
// may lie further than 1e-9 of that distance off the line. Points within 1e-9 of their distance
// from the origin of each other coincide (rounding spreads copies of one point by about 1e-16 of
// it, in any direction). (A singular value decomposition of the 3 x n points said the same for
// lines, but compiling Eigen's JacobiSVD of a dynamic-width matrix took over a minute of the
// sanitizer build.)
bool Collinear(const Eigen::Matrix3Xd& points) {
  const Eigen::Vector3d mean = points.rowwise().mean();
  const Eigen::Matrix3Xd centred = points.colwise() - mean;
  Eigen::Index far = 0;
  const double reach = std::sqrt(centred.colwise().squaredNorm().maxCoeff(&far));
  if (!(reach > 1e-9 * mean.norm())) return true;
  const Eigen::Vector3d direction = centred.col(far) / reach;
  double off_line = 0;
  for (Eigen::Index i = 0; i < centred.cols(); ++i) {
    const Eigen::Vector3d p = centred.col(i);
    off_line = std::max(off_line, (p - p.dot(direction) * direction).norm());
  }
  return off_line <= 1e-9 * reach;
}

}  // namespace

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
  if (extent <= 0 || Collinear(src))
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
