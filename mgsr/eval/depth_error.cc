#include "mgsr/eval/depth_error.h"

#include <algorithm>
#include <cmath>

namespace mgsr {
namespace {

double MedianOf(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t half = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + half, v.end());
  return v[half];
}

// Calls f(index, error, error in footprints) for every pixel that counts: a true depth, a finite
// positive render, and (with a mask of the same size) mask >= 0.5. error = true - rendered.
template <typename F>
void ForEachCountedPixel(const Image& rendered, const Image& truth, const Image* mask,
                         const Camera& camera, F&& f) {
  if (!rendered.SameShape(truth) || rendered.channels() != 1) return;
  const bool masked = mask != nullptr && !mask->empty() && mask->width() == truth.width() &&
                      mask->height() == truth.height();
  const double focal = std::max(camera.fx, camera.fy);
  for (size_t k = 0; k < truth.size(); ++k) {
    const float z_true = truth.data()[k], z = rendered.data()[k];
    if (!(z_true > 0) || !(z > 0) || !std::isfinite(z)) continue;
    if (masked && mask->data()[k] < 0.5f) continue;
    const double e = static_cast<double>(z_true) - z;
    f(k, e, e / (z_true / focal));
  }
}

}  // namespace

void DepthErrorAccumulator::Add(const Image& rendered, const Image& truth, const Image* mask,
                                const Camera& camera) {
  ForEachCountedPixel(rendered, truth, mask, camera, [this](size_t, double e, double px) {
    error_.push_back(e);
    footprints_.push_back(px);
  });
}

Image SignedDepthErrorImage(const Image& rendered, const Image& truth, const Image* mask,
                            const Camera& camera, double range_footprints) {
  Image out(truth.width(), truth.height(), 3, 0.0f);
  if (!(range_footprints > 0)) return out;
  const size_t plane = truth.size();
  ForEachCountedPixel(rendered, truth, mask, camera, [&](size_t k, double, double px) {
    const double u = std::clamp(px / range_footprints, -1.0, 1.0);  // > 0: in front of the truth
    out.data()[k] = static_cast<float>(u > 0 ? 1.0 : 1.0 + u);
    out.data()[plane + k] = static_cast<float>(1.0 - std::abs(u));
    out.data()[2 * plane + k] = static_cast<float>(u < 0 ? 1.0 : 1.0 - u);
  });
  return out;
}

DepthErrorStats DepthErrorAccumulator::Finish() const {
  DepthErrorStats s;
  s.pixels = error_.size();
  if (error_.empty()) return s;
  double sum = 0, abs_sum = 0, beyond = 0;
  for (size_t i = 0; i < error_.size(); ++i) {
    sum += error_[i];
    abs_sum += std::abs(error_[i]);
    beyond += std::abs(footprints_[i]) > 1.0;
  }
  s.mean = sum / error_.size();
  s.mean_abs = abs_sum / error_.size();
  s.share_beyond_footprint = beyond / error_.size();
  s.median = MedianOf(error_);
  s.median_footprints = MedianOf(footprints_);
  return s;
}

}  // namespace mgsr
