#include "solvers/exposure_model.h"

#include <cmath>

namespace mgsr {

void ExposureModel::Reset(int num_views, ExposureMode mode, const std::vector<int>& trained) {
  mode_ = mode;
  trained_ = trained;
  if (trained_.empty()) {
    for (int v = 0; v < num_views; ++v) trained_.push_back(v);
  }

  transforms_.assign(num_views, IdentityColorTransform());
  m_.assign(num_views, ColorTransform{});
  v_.assign(num_views, ColorTransform{});
  steps_.assign(num_views, 0);
}

void ExposureModel::SetTransform(int view, const ColorTransform& p) {
  transforms_[view] = p;
  m_[view] = ColorTransform{};
  v_[view] = ColorTransform{};
  steps_[view] = 0;
}

void ExposureModel::Step(int view, const ColorTransform& gradient, double learning_rate,
                         double prior_weight, double offset_prior, double mean_prior) {
  constexpr double kBeta1 = 0.9, kBeta2 = 0.999, kEps = 1e-15;
  const ColorTransform identity = IdentityColorTransform();
  ColorTransform& p = transforms_[view];
  ColorTransform& m = m_[view];
  ColorTransform& v = v_[view];
  const int t = ++steps_[view];
  // The mean over the trained views, summed afresh (a running sum would drift from one recomputed
  // after a checkpoint, and resumed runs must equal uninterrupted ones bit for bit).
  ColorTransform mean_p{};
  for (int u : trained_) {
    for (int i = 0; i < kColorTransformSize; ++i) mean_p[i] += transforms_[u][i];
  }
  for (double& x : mean_p) x /= static_cast<double>(trained_.size());
  const double c1 = 1 - std::pow(kBeta1, t), c2 = 1 - std::pow(kBeta2, t);
  for (int i = 0; i < kColorTransformSize; ++i) {
    if (!ColorTransformParameterIsFree(mode_, i)) continue;
    const double w = i < 9 ? prior_weight : offset_prior;
    const double mean = mean_p[i];
    const double g =
        gradient[i] + 2 * w * (p[i] - identity[i]) + 2 * mean_prior * (mean - identity[i]);
    m[i] = kBeta1 * m[i] + (1 - kBeta1) * g;
    v[i] = kBeta2 * v[i] + (1 - kBeta2) * g * g;
    p[i] -= learning_rate * (m[i] / c1) / (std::sqrt(v[i] / c2) + kEps);
  }
}

std::vector<double> ExposureModel::SaveState() const {
  std::vector<double> out;
  for (int v = 0; v < num_views(); ++v) {
    for (const ColorTransform* a : {&transforms_[v], &m_[v], &v_[v]}) {
      out.insert(out.end(), a->begin(), a->end());
    }
    out.push_back(steps_[v]);
  }
  return out;
}

bool ExposureModel::LoadState(const std::vector<double>& state, int num_views, ExposureMode mode,
                              const std::vector<int>& trained) {
  constexpr size_t kPerView = 3 * kColorTransformSize + 1;
  if (state.size() != kPerView * static_cast<size_t>(num_views)) return false;
  Reset(num_views, mode, trained);
  for (int v = 0; v < num_views; ++v) {
    const double* s = state.data() + kPerView * v;
    for (int i = 0; i < kColorTransformSize; ++i) {
      transforms_[v][i] = s[i];
      m_[v][i] = s[kColorTransformSize + i];
      v_[v][i] = s[2 * kColorTransformSize + i];
    }
    steps_[v] = static_cast<int>(s[3 * kColorTransformSize]);
  }
  return true;
}

}  // namespace mgsr
