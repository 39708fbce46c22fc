#include "solvers/density_control.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "mgsr/model/activations.h"

namespace mgsr {
namespace {

// What differs between the branches: how many scale axes, and where a child is sampled.
struct GaussianTraits {
  static constexpr int kScales = 3;
};
struct SurfelTraits {
  static constexpr int kScales = 2;
};

template <typename Model, typename Traits>
DensifyResult Densify(Model* m, Adam* adam, DensityStats* stats, const DensityOptions& o,
                      double extent, bool prune_large, Rng* rng) {
  DensifyResult result;
  const size_t n = m->size();
  const float dense = static_cast<float>(o.percent_dense * extent);
  auto max_scale = [&](size_t i) {
    float s = m->log_scales[Traits::kScales * i];
    for (int k = 1; k < Traits::kScales; ++k)
      s = std::max(s, m->log_scales[Traits::kScales * i + k]);
    return std::exp(s);
  };
  // Candidates by average screen gradient, highest first so a budget keeps the most needed.
  std::vector<size_t> candidates;
  std::vector<float> avg(n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    avg[i] = stats->count[i] > 0 ? stats->grad_sum[i] / stats->count[i] : 0.0f;
    if (avg[i] >= o.grad_threshold) candidates.push_back(i);
  }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [&](size_t a, size_t b) { return avg[a] > avg[b]; });
  size_t room = o.max_primitives > 0 ? (o.max_primitives > n ? o.max_primitives - n : 0) : SIZE_MAX;
  std::vector<int> clone, split;
  for (size_t i : candidates) {
    const bool small = max_scale(i) <= dense;
    const size_t cost =
        1;  // a clone adds one row; a split adds two children and removes the parent
    if (room < cost) break;
    room -= cost;
    (small ? clone : split).push_back(static_cast<int>(i));
  }
  // Clone: exact copies.
  if (!clone.empty()) {
    m->AppendCopies(clone);
    adam->AppendZeroRows(clone.size());
    result.cloned = clone.size();
  }
  // Split: two children per parent at points drawn from the parent's Gaussian, scales / 1.6.
  if (!split.empty()) {
    std::vector<int> twice;
    for (int i : split) {
      twice.push_back(i);
      twice.push_back(i);
    }
    const size_t first = m->size();
    m->AppendCopies(twice);
    adam->AppendZeroRows(twice.size());
    for (size_t c = 0; c < twice.size(); ++c) {
      const size_t row = first + c;
      float R[9], q_unit[4];
      QuaternionToRotation(&m->quats[4 * row], R, q_unit);
      float local[3] = {0, 0, 0};
      for (int k = 0; k < Traits::kScales; ++k) {
        local[k] =
            static_cast<float>(rng->Normal()) * std::exp(m->log_scales[Traits::kScales * row + k]);
      }
      for (int r = 0; r < 3; ++r) {
        m->means[3 * row + r] +=
            R[3 * r] * local[0] + R[3 * r + 1] * local[1] + R[3 * r + 2] * local[2];
      }
      for (int k = 0; k < Traits::kScales; ++k)
        m->log_scales[Traits::kScales * row + k] -= std::log(1.6f);
    }
    std::vector<uint8_t> keep(m->size(), 1);
    for (int i : split) keep[i] = 0;
    m->KeepRows(keep);
    adam->KeepRows(keep);
    result.split = split.size();
  }
  // Prune: transparent, or (after the first reset) larger than a tenth of the scene.
  std::vector<uint8_t> keep(m->size(), 1);
  size_t pruned = 0;
  for (size_t i = 0; i < m->size(); ++i) {
    const bool transparent = Sigmoid(m->opacity_logits[i]) < o.min_opacity;
    const bool large = prune_large && max_scale(i) > o.max_world_size * extent;
    if (transparent || large) {
      keep[i] = 0;
      ++pruned;
    }
  }
  if (pruned > 0 && pruned < m->size()) {  // never prune everything
    m->KeepRows(keep);
    adam->KeepRows(keep);
    result.pruned = pruned;
  }
  stats->Reset(m->size());
  return result;
}

void CapLogit(std::vector<float>* logits, float max_value) {
  const float cap = InverseSigmoid(max_value);
  for (float& x : *logits) x = std::min(x, cap);
}

}  // namespace

DensifyResult DensifyAndPrune(GaussianModel* model, Adam* adam, DensityStats* stats,
                              const DensityOptions& options, double extent, bool prune_large,
                              Rng* rng) {
  return Densify<GaussianModel, GaussianTraits>(model, adam, stats, options, extent, prune_large,
                                                rng);
}

DensifyResult DensifyAndPrune(SurfelModel* model, Adam* adam, DensityStats* stats,
                              const DensityOptions& options, double extent, bool prune_large,
                              Rng* rng) {
  return Densify<SurfelModel, SurfelTraits>(model, adam, stats, options, extent, prune_large, rng);
}

void ResetOpacity(GaussianModel* m, Adam* adam) {
  CapLogit(&m->opacity_logits, 0.01f);
  CapLogit(&m->ref_opacity_logits, 0.01f);
  CapLogit(&m->beta_logits, 0.1f);
  for (const char* b : {"opacity_logits", "ref_opacity_logits", "beta_logits"}) adam->ResetBlock(b);
}

void ResetOpacity(SurfelModel* m, Adam* adam) {
  CapLogit(&m->opacity_logits, 0.01f);
  adam->ResetBlock("opacity_logits");
}

size_t DefaultPrimitiveBudget(const Scene& scene) {
  size_t pixels = 0;
  for (int i : scene.TrainIndices()) {
    const Camera& c = scene.views[i].camera;
    pixels = std::max(pixels, static_cast<size_t>(c.width) * static_cast<size_t>(c.height));
  }
  return std::max(kMinBudget, kBudgetPerPixel * pixels);
}

}  // namespace mgsr
