#include "solvers/exposure_fit.h"

#include <ceres/ceres.h>

#include <cmath>
#include <vector>

namespace mgsr {
namespace {

// Three residuals of one pixel: (A c + b) - photo.
struct PixelResidual {
  PixelResidual(const float* c, const float* y) : c_{c[0], c[1], c[2]}, y_{y[0], y[1], y[2]} {}
  template <typename T>
  bool operator()(const T* p, T* r) const {
    for (int o = 0; o < 3; ++o) {
      r[o] = p[3 * o] * c_[0] + p[3 * o + 1] * c_[1] + p[3 * o + 2] * c_[2] + p[9 + o] - y_[o];
    }
    return true;
  }
  double c_[3], y_[3];
};

// sqrt(weight) * b: the prior on the offsets.
struct OffsetPrior {
  explicit OffsetPrior(double sqrt_weight) : w_(sqrt_weight) {}
  template <typename T>
  bool operator()(const T* p, T* r) const {
    for (int o = 0; o < 3; ++o) r[o] = w_ * p[9 + o];
    return true;
  }
  double w_;
};

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

  ColorTransform p = IdentityColorTransform();
  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  ceres::HuberLoss huber(options.huber_delta);
  int samples = 0;
  for (size_t k = 0; k < usable.size(); k += stride) {
    const size_t i = usable[k];
    const float c[3] = {render.plane(0)[i], render.plane(1)[i], render.plane(2)[i]};
    const float y[3] = {photo.plane(0)[i], photo.plane(1)[i], photo.plane(2)[i]};
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PixelResidual, 3, kColorTransformSize>(
                                 new PixelResidual(c, y)),
                             &huber, p.data());
    ++samples;
  }
  if (options.offset_prior > 0) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<OffsetPrior, 3, kColorTransformSize>(
                                 new OffsetPrior(std::sqrt(options.offset_prior * samples))),
                             nullptr, p.data());
  }
  std::vector<int> fixed;
  for (int i = 0; i < kColorTransformSize; ++i) {
    if (!ColorTransformParameterIsFree(options.mode, i)) fixed.push_back(i);
  }
  if (!fixed.empty()) {
    problem.SetManifold(p.data(), new ceres::SubsetManifold(kColorTransformSize, fixed));
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 50;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary s;
  ceres::Solve(so, &problem, &s);
  if (!s.IsSolutionUsable()) return Status::Error("exposure fit: " + s.message);
  *out = p;
  if (summary != nullptr) {
    summary->samples = samples;
    summary->initial_cost = s.initial_cost;
    summary->final_cost = s.final_cost;
  }
  return Status::Ok();
}

}  // namespace mgsr
