#include "mgsr/render/visualize.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace mgsr {
namespace {

// A red-to-blue map in the spirit of Google's Turbo (perceptually ordered, dark at both ends),
// as piecewise-linear stops; t = 0 is near.
std::array<float, 3> Turbo(float t) {
  static const float kStops[9][3] = {
      {0.48f, 0.02f, 0.01f}, {0.85f, 0.22f, 0.04f}, {0.99f, 0.53f, 0.13f},
      {0.89f, 0.82f, 0.22f}, {0.64f, 0.99f, 0.24f}, {0.27f, 0.97f, 0.52f},
      {0.10f, 0.80f, 0.87f}, {0.25f, 0.47f, 0.97f}, {0.19f, 0.07f, 0.23f}};
  t = std::clamp(t, 0.0f, 1.0f) * 8;
  const int i = std::min(7, static_cast<int>(t));
  const float f = t - i;
  return {kStops[i][0] + f * (kStops[i + 1][0] - kStops[i][0]),
          kStops[i][1] + f * (kStops[i + 1][1] - kStops[i][1]),
          kStops[i][2] + f * (kStops[i + 1][2] - kStops[i][2])};
}

}  // namespace

DepthRange RenderedDepthRange(const Image& depth, const Image& alpha) {
  std::vector<float> z;
  for (size_t k = 0; k < depth.plane_size(); ++k) {
    const float d = depth.data()[k];
    if (alpha.data()[k] >= 0.5f && std::isfinite(d) && d > 0) z.push_back(d);
  }
  if (z.empty()) return {};
  std::sort(z.begin(), z.end());
  const float lo = z[z.size() * 2 / 100], hi = z[std::min(z.size() - 1, z.size() * 98 / 100)];
  const float pad = std::max(0.02f * (hi - lo), 1e-6f * hi);
  return {lo - pad, hi + pad};
}

Image DepthColormap(const Image& depth, const Image& alpha, const DepthRange& range) {
  Image out(depth.width(), depth.height(), 3);
  const float span = range.far - range.near;
  for (size_t k = 0; k < depth.plane_size(); ++k) {
    if (alpha.data()[k] < 0.5f || !(span > 0)) continue;
    const auto rgb = Turbo((depth.data()[k] - range.near) / span);
    for (int c = 0; c < 3; ++c) out.plane(c)[k] = rgb[c];
  }
  return out;
}

Image NormalColormap(const Image& normal, const Image& alpha) {
  Image out(normal.width(), normal.height(), 3);
  for (size_t k = 0; k < normal.plane_size(); ++k) {
    if (alpha.data()[k] < 0.5f) continue;
    float n[3], len = 0;
    for (int c = 0; c < 3; ++c) {
      n[c] = normal.plane(c)[k];
      len += n[c] * n[c];
    }
    len = len > 0 ? 1 / std::sqrt(len) : 0;
    for (int c = 0; c < 3; ++c) out.plane(c)[k] = 0.5f + 0.5f * n[c] * len;
  }
  return out;
}

}  // namespace mgsr
