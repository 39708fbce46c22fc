#include "solvers/backdrop.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

namespace mgsr {
namespace {

// The q-quantile (0 <= q < 1) of a non-empty sample; reorders it.
float Quantile(std::vector<float>* v, double q) {
  auto at = v->begin() + static_cast<size_t>(v->size() * q);
  std::nth_element(v->begin(), at, v->end());
  return *at;
}

}  // namespace

Backdrop EstimateBackdrop(const Scene& scene, const BackdropOptions& options) {
  Backdrop out;
  std::vector<float> samples[3];
  for (int index : scene.TrainIndices()) {
    const View& v = scene.views[index];
    if (!v.mask.empty() || !v.alpha.empty()) {
      out.reason = v.name + " has a mask or alpha";
      return out;
    }
    if (v.image.empty()) continue;
    const int w = v.image.width(), h = v.image.height();
    const int ring = std::max(1, static_cast<int>(std::min(w, h) * options.border_fraction));
    for (int y = 0; y < h; ++y) {
      const bool band = y < ring || y >= h - ring;
      for (int x = 0; x < w; ++x) {
        if (!band && x >= ring && x < w - ring) x = w - ring;  // skip the interior of the row
        const size_t i = static_cast<size_t>(y) * w + x;
        for (int c = 0; c < 3; ++c) samples[c].push_back(v.image.plane(c)[i]);
      }
    }
  }
  if (samples[0].empty()) {
    out.reason = "no training photos";
    return out;
  }
  float median[3];
  for (int c = 0; c < 3; ++c) median[c] = Quantile(&samples[c], 0.5);
  const float level = (median[0] + median[1] + median[2]) / 3;
  std::vector<float> deviation;
  deviation.reserve(samples[0].size() * 3);
  for (int c = 0; c < 3; ++c) {
    for (float s : samples[c]) deviation.push_back(std::abs(s - median[c]));
  }
  out.spread = Quantile(&deviation, 0.8);
  float tint = 0;
  for (float m : median) tint = std::max(tint, std::abs(m - level));
  std::ostringstream why;
  if (out.spread > options.max_spread) {
    why << "the photos' borders vary (spread " << out.spread << " > " << options.max_spread << ")";
  } else if (tint > options.max_tint) {
    why << "the backdrop is coloured (" << median[0] << ", " << median[1] << ", " << median[2]
        << "), not grey";
  }
  out.reason = why.str();
  out.uniform = out.reason.empty();
  out.level = level;
  return out;
}

}  // namespace mgsr
