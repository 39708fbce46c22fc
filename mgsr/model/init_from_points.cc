#include "mgsr/model/init_from_points.h"

#include <glog/logging.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <nanoflann.hpp>

#include "mgsr/core/rng.h"
#include "mgsr/model/activations.h"

namespace mgsr {
namespace {

struct Cloud {
  const std::vector<Eigen::Vector3f>& pts;
  size_t kdtree_get_point_count() const { return pts.size(); }
  float kdtree_get_pt(size_t i, size_t d) const { return pts[i][d]; }
  template <class B>
  bool kdtree_get_bbox(B&) const {
    return false;
  }
};
using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Cloud>, Cloud,
                                                 3, size_t>;

constexpr float kInitOpacity = 0.1f;

}  // namespace

std::vector<float> MeanSquaredNeighbourDistance(const std::vector<Eigen::Vector3f>& points, int k) {
  std::vector<float> out(points.size(), 1e-7f);
  if (points.size() < 2) return out;
  Cloud cloud{points};
  Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const int want =
      std::min<int>(k + 1, static_cast<int>(points.size()));  // the point itself comes first
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < static_cast<int64_t>(points.size()); ++i) {
    size_t idx[16];
    float d2[16];
    const size_t found = tree.knnSearch(points[i].data(), want, idx, d2);
    double sum = 0;
    int used = 0;
    for (size_t q = 0; q < found; ++q) {
      if (idx[q] == static_cast<size_t>(i)) continue;
      sum += d2[q];
      ++used;
      if (used == k) break;
    }
    out[i] = std::max(1e-7f, used > 0 ? static_cast<float>(sum / used) : 1e-7f);
  }
  return out;
}

void InitGaussiansFromPoints(const std::vector<Eigen::Vector3f>& points,
                             const std::vector<Eigen::Vector3f>& colors, int max_sh_degree,
                             GaussianModel* m) {
  CHECK_EQ(points.size(), colors.size());
  CHECK_LE(max_sh_degree, 3);
  *m = GaussianModel();
  m->max_sh_degree = max_sh_degree;
  m->Resize(points.size());
  std::fill(m->sh.begin(), m->sh.end(), 0.0f);
  std::fill(m->ref_sh.begin(), m->ref_sh.end(), 0.0f);
  const std::vector<float> d2 = MeanSquaredNeighbourDistance(points, 3);
  const int K = m->sh_coeffs();
  const float logit = InverseSigmoid(kInitOpacity);
  for (size_t i = 0; i < points.size(); ++i) {
    const float log_scale = std::log(std::sqrt(d2[i]));
    for (int d = 0; d < 3; ++d) {
      m->means[3 * i + d] = points[i][d];
      m->log_scales[3 * i + d] = log_scale;
      m->sh[i * K * 3 + d] = RgbToShDc(colors[i][d]);
      m->ref_sh[i * K * 3 + d] = RgbToShDc(colors[i][d]);
    }
    m->quats[4 * i] = 1.0f;
    m->quats[4 * i + 1] = m->quats[4 * i + 2] = m->quats[4 * i + 3] = 0.0f;
    m->opacity_logits[i] = logit;
    m->ref_opacity_logits[i] = logit;
    m->beta_logits[i] = logit;
  }
}

std::vector<float> NeighbourhoodRotations(const std::vector<Eigen::Vector3f>& points, int k) {
  std::vector<float> out(4 * points.size(), 0.0f);
  for (size_t i = 0; i < points.size(); ++i) out[4 * i] = 1.0f;
  if (points.size() < 3) return out;
  Cloud cloud{points};
  Tree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const int want = std::max(3, std::min<int>(k, static_cast<int>(points.size())));
#pragma omp parallel
  {
    std::vector<size_t> idx(want);
    std::vector<float> d2(want);
#pragma omp for schedule(static)
    for (int64_t i = 0; i < static_cast<int64_t>(points.size()); ++i) {
      const size_t found = tree.knnSearch(points[i].data(), want, idx.data(), d2.data());
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (size_t q = 0; q < found; ++q) mean += points[idx[q]].cast<double>();
      mean /= static_cast<double>(found);
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (size_t q = 0; q < found; ++q) {
        const Eigen::Vector3d d = points[idx[q]].cast<double>() - mean;
        cov += d * d.transpose();
      }
      // Eigenvalues ascend: the last two vectors span the plane, the first is its normal.
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
      Eigen::Matrix3d r;
      r.col(0) = eig.eigenvectors().col(2);
      r.col(1) = eig.eigenvectors().col(1);
      r.col(2) = r.col(0).cross(r.col(1));
      const Eigen::Quaterniond q(r);
      out[4 * i] = static_cast<float>(q.w());
      out[4 * i + 1] = static_cast<float>(q.x());
      out[4 * i + 2] = static_cast<float>(q.y());
      out[4 * i + 3] = static_cast<float>(q.z());
    }
  }
  return out;
}

void SpreadPointsOverTheirSurfaces(size_t target, uint64_t seed,
                                   std::vector<Eigen::Vector3f>* points,
                                   std::vector<Eigen::Vector3f>* colors, int k) {
  CHECK_EQ(points->size(), colors->size());
  const size_t n = points->size();
  if (target <= n || n < 3) return;
  const std::vector<float> d2 = MeanSquaredNeighbourDistance(*points, 3);
  const std::vector<float> rotations = NeighbourhoodRotations(*points, k);
  std::vector<Eigen::Vector3f> spread, spread_colors;
  spread.reserve(target);
  spread_colors.reserve(target);
  Rng rng(seed);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Matrix3f r = Eigen::Quaternionf(rotations[4 * i], rotations[4 * i + 1],
                                                 rotations[4 * i + 2], rotations[4 * i + 3])
                                  .toRotationMatrix();
    const float radius = 0.5f * std::sqrt(d2[i]);
    // Point i's share of the target: the first (i + 1) n-ths minus the first i, so they sum to it.
    const size_t share = target * (i + 1) / n - target * i / n;
    spread.push_back((*points)[i]);
    spread_colors.push_back((*colors)[i]);
    for (size_t c = 1; c < share; ++c) {
      double u, v;
      do {  // uniform in the unit disk by rejection
        u = 2 * rng.Uniform() - 1;
        v = 2 * rng.Uniform() - 1;
      } while (u * u + v * v > 1);
      spread.push_back((*points)[i] + radius * (static_cast<float>(u) * r.col(0) +
                                                static_cast<float>(v) * r.col(1)));
      spread_colors.push_back((*colors)[i]);
    }
  }
  points->swap(spread);
  colors->swap(spread_colors);
}

void InitSurfelsFromPoints(const std::vector<Eigen::Vector3f>& points,
                           const std::vector<Eigen::Vector3f>& colors, int max_sh_degree,
                           uint64_t seed, SurfelModel* m, SurfelOrientation orientation) {
  CHECK_EQ(points.size(), colors.size());
  CHECK_LE(max_sh_degree, 3);
  *m = SurfelModel();
  m->max_sh_degree = max_sh_degree;
  m->Resize(points.size());
  std::fill(m->sh.begin(), m->sh.end(), 0.0f);
  const std::vector<float> d2 = MeanSquaredNeighbourDistance(points, 3);
  const int K = m->sh_coeffs();
  const float logit = InverseSigmoid(kInitOpacity);
  Rng rng(seed);
  for (size_t i = 0; i < points.size(); ++i) {
    const float log_scale = std::log(std::sqrt(d2[i]));
    for (int d = 0; d < 3; ++d) {
      m->means[3 * i + d] = points[i][d];
      m->sh[i * K * 3 + d] = RgbToShDc(colors[i][d]);
    }
    m->log_scales[2 * i] = m->log_scales[2 * i + 1] = log_scale;
    // The reference draws U(0,1)^4 and normalises on use; same here, seeded.
    if (orientation == SurfelOrientation::kRandom) {
      for (int d = 0; d < 4; ++d) m->quats[4 * i + d] = static_cast<float>(rng.Uniform());
    }
    m->opacity_logits[i] = logit;
  }
  if (orientation == SurfelOrientation::kNeighbourhood) m->quats = NeighbourhoodRotations(points);
}

}  // namespace mgsr
