#include "solvers/exposure_fit.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

namespace mgsr {
namespace {

// One sample: the render's colour (with a 1 for the offset) and the photo's.
struct Sample {
  double phi[4];
  double y[3];
};

// Ceres' convention for a robust loss on a block's squared norm s: rho(s) = s up to delta^2, then
// 2 delta sqrt(s) - delta^2; its derivative is the IRLS weight.
double Huber(double s, double delta) {
  return s <= delta * delta ? s : 2 * delta * std::sqrt(s) - delta * delta;
}
double HuberWeight(double s, double delta) {
  return s <= delta * delta ? 1.0 : delta / std::sqrt(s);
}

double SquaredResidual(const ColorTransform& p, const Sample& k) {
  double s = 0;
  for (int o = 0; o < 3; ++o) {
    const double r =
        p[3 * o] * k.phi[0] + p[3 * o + 1] * k.phi[1] + p[3 * o + 2] * k.phi[2] + p[9 + o] - k.y[o];
    s += r * r;
  }
  return s;
}

// 1/2 sum rho(|A c + b - y|^2) + 1/2 prior |b|^2: the cost Ceres would report.
double Cost(const ColorTransform& p, const std::vector<Sample>& samples, double delta,
            double prior) {
  double c = 0;
  for (const Sample& k : samples) c += Huber(SquaredResidual(p, k), delta);
  for (int o = 0; o < 3; ++o) c += prior * p[9 + o] * p[9 + o];
  return 0.5 * c;
}

}  // namespace

Status FitColorTransform(const Image& render, const Image& photo, const Image* mask,
                         const ExposureFitOptions& options, ColorTransform* out,
                         ExposureFitSummary* summary) {
  if (render.channels() != 3 || photo.channels() != 3 || render.width() != photo.width() ||
      render.height() != photo.height()) {
    return Status::Error("exposure fit: render and photo must be RGB images of the same size");
  }
  if (mask != nullptr && (mask->width() != render.width() || mask->height() != render.height()))
    return Status::Error("exposure fit: mask size differs from the render");
  *out = IdentityColorTransform();
  if (options.mode == ExposureMode::kOff) return Status::Ok();

  std::vector<size_t> usable;
  const size_t n = render.plane_size();
  for (size_t i = 0; i < n; ++i) {
    if (mask != nullptr && !(mask->plane(0)[i] > options.mask_threshold)) continue;
    bool ok = true;
    for (int c = 0; c < 3 && ok; ++c) {
      ok = photo.plane(c)[i] < options.saturation && std::isfinite(render.plane(c)[i]);
    }
    if (ok) usable.push_back(i);
  }
  if (usable.size() < 16) return Status::Error("exposure fit: fewer than 16 usable pixels");
  const size_t stride = std::max<size_t>(1, usable.size() / std::max(1, options.max_samples));
  std::vector<Sample> samples;
  for (size_t k = 0; k < usable.size(); k += stride) {
    const size_t i = usable[k];
    Sample s;
    for (int c = 0; c < 3; ++c) {
      s.phi[c] = render.plane(c)[i];
      s.y[c] = photo.plane(c)[i];
    }
    s.phi[3] = 1;
    samples.push_back(s);
  }
  const double delta = options.huber_delta;
  const double prior = options.offset_prior > 0 ? options.offset_prior * samples.size() : 0.0;

  // Iteratively reweighted least squares: the Huber cost is convex, and each step minimises its
  // quadratic majoriser at the current residuals, so the cost falls monotonically to the minimum.
  // With the pixel weights fixed, the three output channels separate into least-squares problems
  // over (A_o0, A_o1, A_o2, b_o) that share one 4x4 normal matrix; parameters the mode holds at
  // identity move to the right-hand side.
  ColorTransform p = IdentityColorTransform();
  const double initial_cost = Cost(p, samples, delta, prior);
  for (int iteration = 0; iteration < 100; ++iteration) {
    Eigen::Matrix4d normal = Eigen::Matrix4d::Zero();
    Eigen::Matrix<double, 4, 3> rhs = Eigen::Matrix<double, 4, 3>::Zero();
    for (const Sample& k : samples) {
      const double u = HuberWeight(SquaredResidual(p, k), delta);
      const Eigen::Map<const Eigen::Vector4d> phi(k.phi);
      normal.noalias() += u * phi * phi.transpose();
      for (int o = 0; o < 3; ++o) rhs.col(o) += (u * k.y[o]) * phi;
    }
    normal(3, 3) += prior;
    ColorTransform next = p;
    for (int o = 0; o < 3; ++o) {
      const int index[4] = {3 * o, 3 * o + 1, 3 * o + 2, 9 + o};
      int free[4], num_free = 0;
      Eigen::Vector4d fixed_part = Eigen::Vector4d::Zero();
      for (int j = 0; j < 4; ++j) {
        if (ColorTransformParameterIsFree(options.mode, index[j])) {
          free[num_free++] = j;
        } else {
          fixed_part += normal.col(j) * p[index[j]];
        }
      }
      if (num_free == 0) continue;
      Eigen::MatrixXd m(num_free, num_free);
      Eigen::VectorXd b(num_free);
      for (int a = 0; a < num_free; ++a) {
        b(a) = rhs(free[a], o) - fixed_part(free[a]);
        for (int c = 0; c < num_free; ++c) m(a, c) = normal(free[a], free[c]);
      }
      const Eigen::VectorXd theta = m.ldlt().solve(b);
      if (!theta.allFinite()) return Status::Error("exposure fit: singular normal equations");
      for (int a = 0; a < num_free; ++a) next[index[free[a]]] = theta(a);
    }
    double change = 0;
    for (int j = 0; j < kColorTransformSize; ++j)
      change = std::max(change, std::abs(next[j] - p[j]));
    p = next;
    if (change < 1e-9) break;
  }
  *out = p;
  if (summary != nullptr) {
    summary->samples = static_cast<int>(samples.size());
    summary->initial_cost = initial_cost;
    summary->final_cost = Cost(p, samples, delta, prior);
  }
  return Status::Ok();
}

}  // namespace mgsr
