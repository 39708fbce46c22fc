#include "solvers/density_control.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>

#include "mgsr/model/activations.h"

namespace mgsr {
DensifyResult DensifyAndPrune(PrimitiveRows* rows, DensityStats* stats, const DensityOptions& o,
                              double extent, bool prune_large, Rng* rng) {
  DensifyResult result;
  const int axes = rows->layout().scale_axes;
  const size_t n = rows->size();
  const float dense = static_cast<float>(o.percent_dense * extent);
  auto max_scale = [&](size_t i) {
    const float* log_scales = rows->Block("log_scales");
    float s = log_scales[axes * i];
    for (int k = 1; k < axes; ++k) s = std::max(s, log_scales[axes * i + k]);
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
    // A clone adds one row; a split adds two children and removes the parent.
    if (room < 1) break;
    room -= 1;
    (small ? clone : split).push_back(static_cast<int>(i));
  }
  // Clone: exact copies.
  rows->AppendCopies(clone);
  result.cloned = clone.size();
  // Split: two children per parent at points drawn from the parent's Gaussian, scales / 1.6.
  if (!split.empty()) {
    std::vector<int> twice;
    for (int i : split) {
      twice.push_back(i);
      twice.push_back(i);
    }
    const size_t first = rows->size();
    rows->AppendCopies(twice);
    float* means = rows->Block("means");
    float* log_scales = rows->Block("log_scales");
    const float* quats = rows->Block("quats");
    for (size_t c = 0; c < twice.size(); ++c) {
      const size_t row = first + c;
      float R[9], q_unit[4];
      QuaternionToRotation(&quats[4 * row], R, q_unit);
      float local[3] = {0, 0, 0};
      for (int k = 0; k < axes; ++k)
        local[k] = static_cast<float>(rng->Normal()) * std::exp(log_scales[axes * row + k]);
      for (int r = 0; r < 3; ++r)
        means[3 * row + r] +=
            R[3 * r] * local[0] + R[3 * r + 1] * local[1] + R[3 * r + 2] * local[2];
      for (int k = 0; k < axes; ++k) log_scales[axes * row + k] -= std::log(1.6f);
    }
    std::vector<uint8_t> keep(rows->size(), 1);
    for (int i : split) keep[i] = 0;
    rows->KeepRows(keep);
    result.split = split.size();
  }
  // Prune: transparent, or (after the first reset) larger than a tenth of the scene.
  std::vector<uint8_t> keep(rows->size(), 1);
  size_t pruned = 0;
  const float* opacity_logits = rows->Block("opacity_logits");
  for (size_t i = 0; i < rows->size(); ++i) {
    const bool transparent = Sigmoid(opacity_logits[i]) < o.min_opacity;
    const bool large = prune_large && max_scale(i) > o.max_world_size * extent;
    if (transparent || large) {
      keep[i] = 0;
      ++pruned;
    }
  }
  if (pruned > 0 && pruned < rows->size()) {  // never prune everything
    rows->KeepRows(keep);
    result.pruned = pruned;
  }
  stats->Reset(rows->size());
  return result;
}

size_t DefaultPrimitiveBudget(const Scene& scene) {
  size_t pixels = 0;
  for (int i : scene.TrainIndices()) {
    const Camera& c = scene.views[i].camera;
    pixels = std::max(pixels, static_cast<size_t>(c.width) * static_cast<size_t>(c.height));
  }
  return std::max(kMinBudget, kBudgetPerPixel * pixels);
}

SceneBudget AutoPrimitiveBudget(const Scene& scene) {
  std::vector<double> counts;
  std::string source = "every pixel (no masks or alpha)";
  for (int i : scene.TrainIndices()) {
    const View& v = scene.views[i];
    const Image* cover = !v.mask.empty() ? &v.mask : !v.alpha.empty() ? &v.alpha : nullptr;
    double n = static_cast<double>(v.camera.width) * v.camera.height;
    if (cover != nullptr) {
      source = !v.mask.empty() ? "mask" : "alpha";
      n = 0;
      for (int y = 0; y < cover->height(); ++y)
        for (int x = 0; x < cover->width(); ++x) n += cover->at(0, y, x) > 0.5f ? 1 : 0;
    }
    counts.push_back(n);
  }
  SceneBudget b;
  if (!counts.empty()) {
    std::nth_element(counts.begin(), counts.begin() + counts.size() / 2, counts.end());
    b.foreground_pixels = counts[counts.size() / 2];
  }
  const double size = std::sqrt(b.foreground_pixels);
  auto budget = [&](double rate) {
    return std::max(kMinAutoBudget, static_cast<size_t>(std::lround(rate * size)));
  };
  b.gaussians = budget(kAutoGaussiansPerSqrtPixel);
  b.surfels = budget(kAutoSurfelsPerSqrtPixel);
  char why[256];
  std::snprintf(why, sizeof(why),
                "auto: %.0f Gaussians and %.0f surfels x sqrt(foreground pixels of the median "
                "training view: %.0f by %s), at least %zu",
                kAutoGaussiansPerSqrtPixel, kAutoSurfelsPerSqrtPixel, b.foreground_pixels,
                source.c_str(), kMinAutoBudget);
  b.why = why;
  return b;
}

}  // namespace mgsr
