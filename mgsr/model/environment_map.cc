#include "mgsr/model/environment_map.h"

#include <algorithm>
#include <cmath>

#include "mgsr/loss/parallel_pixels.h"  // views under kParallelPixels run on one thread

namespace mgsr {

void EnvironmentMap::Reset(int w, int h, float value) {
  width = w;
  height = h;
  texels.assign(static_cast<size_t>(w) * h * 3, value);
}

EnvironmentTaps EnvironmentMap::Taps(const Eigen::Vector3d& d) const {
  EnvironmentTaps t;
  if (width <= 0 || height <= 0) return t;
  // Texel centres at (i + 0.5, j + 0.5) in (longitude, latitude) units of the map.
  const double u = (std::atan2(d.y(), d.x()) + M_PI) / (2 * M_PI) * width - 0.5;
  const double v = std::acos(std::clamp(d.z(), -1.0, 1.0)) / M_PI * height - 0.5;
  const double fu = std::floor(u), fv = std::floor(v);
  const double au = u - fu, av = v - fv;
  const int x0 = ((static_cast<int>(fu) % width) + width) % width, x1 = (x0 + 1) % width;
  const int y0 = std::clamp(static_cast<int>(fv), 0, height - 1);
  const int y1 = std::clamp(static_cast<int>(fv) + 1, 0, height - 1);
  t.texel[0] = y0 * width + x0;
  t.texel[1] = y0 * width + x1;
  t.texel[2] = y1 * width + x0;
  t.texel[3] = y1 * width + x1;
  t.weight[0] = (1 - au) * (1 - av);
  t.weight[1] = au * (1 - av);
  t.weight[2] = (1 - au) * av;
  t.weight[3] = au * av;
  return t;
}

namespace {

// atan2(y, x) in float within 2e-6 rad (a minimax polynomial for atan on [0, 1], then the
// octant), without branches so that a loop of it vectorises.
inline float PolynomialAtan2(float y, float x) {
  const float ax = std::abs(x), ay = std::abs(y);
  const float hi = std::max(ax, ay), lo = std::min(ax, ay);
  const float a = hi > 0 ? lo / hi : 0.0f;
  const float s = a * a;
  float r =
      ((((-0.01172120f * s + 0.05265332f) * s - 0.11643287f) * s + 0.19354346f) * s - 0.33262347f) *
          s +
      0.99997726f;
  r *= a;
  r = ay > ax ? 1.57079633f - r : r;
  r = x < 0 ? 3.14159265f - r : r;
  return y < 0 ? -r : r;
}

// Pixels per chunk of a row whose map coordinates are computed together (stack arrays).
constexpr int kChunk = 256;
// Backward's row bands: a fixed number, so that the sum's order does not depend on the threads.
constexpr int kBands = 16;

}  // namespace

const std::vector<EnvironmentRenderer::PixelTaps>& EnvironmentRenderer::TapsFor(
    const EnvironmentMap& map, const Camera& camera) {
  const size_t n = static_cast<size_t>(camera.width) * camera.height;
  if (taps_.size() == n && camera_ == camera && map_width_ == map.width &&
      map_height_ == map.height)
    return taps_;
  taps_.resize(n);
  const int w = map.width, h = map.height;
  if (w <= 0 || h <= 0) {
    for (PixelTaps& t : taps_) t = PixelTaps{0, 0, 0, 0, 0.0f, 0.0f};
  } else {
    // The world direction of pixel (x, y) is Rt K^-1 (x + 0.5, y + 0.5, 1): along a row, a start
    // plus x steps.
    const Eigen::Matrix3d Rt = camera.R.transpose();
    const Eigen::Vector3d step = Rt * Eigen::Vector3d(1.0 / camera.fx, 0, 0);
    const float u_scale = static_cast<float>(w / (2 * M_PI)),
                v_scale = static_cast<float>(h / M_PI);
#pragma omp parallel for schedule(static) if (static_cast <int64_t>(n) >= kParallelPixels)
    for (int y = 0; y < camera.height; ++y) {
      const Eigen::Vector3d row = Rt * camera.PixelToRay(0.5, y + 0.5);
      float u[kChunk], v[kChunk];
      for (int x0 = 0; x0 < camera.width; x0 += kChunk) {
        const int count = std::min(kChunk, camera.width - x0);
        const Eigen::Vector3d start = row + x0 * step;
        const float s0 = static_cast<float>(start.x()), s1 = static_cast<float>(start.y()),
                    s2 = static_cast<float>(start.z());
        const float t0 = static_cast<float>(step.x()), t1 = static_cast<float>(step.y()),
                    t2 = static_cast<float>(step.z());
        for (int i = 0; i < count; ++i) {
          const float dx = s0 + i * t0, dy = s1 + i * t1, dz = s2 + i * t2;
          // Longitude around +z from -pi; polar angle from +z (no normalisation needed).
          u[i] = (PolynomialAtan2(dy, dx) + 3.14159265f) * u_scale - 0.5f;
          v[i] = PolynomialAtan2(std::sqrt(dx * dx + dy * dy), dz) * v_scale - 0.5f;
        }
        PixelTaps* out = &taps_[static_cast<size_t>(y) * camera.width + x0];
        for (int i = 0; i < count; ++i) {
          const float fu = std::floor(u[i]), fv = std::floor(v[i]);
          int ix = static_cast<int>(fu);
          ix = ix < 0 ? ix + w : (ix >= w ? ix - w : ix);
          const int iy = static_cast<int>(fv);
          out[i].x0 = static_cast<uint16_t>(ix);
          out[i].x1 = static_cast<uint16_t>(ix + 1 == w ? 0 : ix + 1);
          out[i].y0 = static_cast<uint16_t>(std::clamp(iy, 0, h - 1));
          out[i].y1 = static_cast<uint16_t>(std::clamp(iy + 1, 0, h - 1));
          out[i].ax = u[i] - fu;
          out[i].ay = v[i] - fv;
        }
      }
    }
  }
  camera_ = camera;
  map_width_ = map.width;
  map_height_ = map.height;
  return taps_;
}

void EnvironmentRenderer::Render(const EnvironmentMap& map, const Camera& camera, Image* out) {
  const std::vector<PixelTaps>& taps = TapsFor(map, camera);
  if (out->width() != camera.width || out->height() != camera.height || out->channels() != 3)
    *out = Image(camera.width, camera.height, 3);
  if (map.width <= 0 || map.height <= 0) {
    out->Fill(0.0f);
    return;
  }
  const float* texels = map.texels.data();
  const int w = map.width;
  float* planes[3] = {out->plane(0), out->plane(1), out->plane(2)};
  const int64_t pixels = static_cast<int64_t>(taps.size());
#pragma omp parallel for schedule(static) if (pixels >= kParallelPixels)
  for (int y = 0; y < camera.height; ++y) {
    const size_t begin = static_cast<size_t>(y) * camera.width;
    for (size_t i = begin; i < begin + camera.width; ++i) {
      int texel[4];
      float weight[4];
      taps[i].Expand(w, texel, weight);
      const float *a = texels + 3 * texel[0], *b = texels + 3 * texel[1],
                  *c = texels + 3 * texel[2], *d = texels + 3 * texel[3];
      for (int k = 0; k < 3; ++k)
        planes[k][i] = weight[0] * a[k] + weight[1] * b[k] + weight[2] * c[k] + weight[3] * d[k];
    }
  }
}

void EnvironmentRenderer::Backward(const EnvironmentMap& map, const Camera& camera,
                                   const Image& grad, std::vector<float>* d_texels) {
  const std::vector<PixelTaps>& taps = TapsFor(map, camera);
  d_texels->resize(map.texels.size(), 0.0f);
  if (map.width <= 0 || map.height <= 0) return;
  const size_t texel_floats = map.texels.size();
  band_sums_.resize(kBands * texel_floats);
  const int w = map.width;
  const float* g[3] = {grad.plane(0), grad.plane(1), grad.plane(2)};
  const int64_t pixels = static_cast<int64_t>(taps.size());
#pragma omp parallel for schedule(dynamic) if (pixels >= kParallelPixels)
  for (int band = 0; band < kBands; ++band) {
    float* sum = band_sums_.data() + band * texel_floats;
    std::fill(sum, sum + texel_floats, 0.0f);
    const int y_begin = static_cast<int>(static_cast<int64_t>(camera.height) * band / kBands);
    const int y_end = static_cast<int>(static_cast<int64_t>(camera.height) * (band + 1) / kBands);
    const size_t end = static_cast<size_t>(y_end) * camera.width;
    for (size_t i = static_cast<size_t>(y_begin) * camera.width; i < end; ++i) {
      const float g0 = g[0][i], g1 = g[1][i], g2 = g[2][i];
      if (g0 == 0 && g1 == 0 && g2 == 0) continue;
      int texel[4];
      float weight[4];
      taps[i].Expand(w, texel, weight);
      for (int k = 0; k < 4; ++k) {
        float* s = sum + 3 * texel[k];
        s[0] += weight[k] * g0;
        s[1] += weight[k] * g1;
        s[2] += weight[k] * g2;
      }
    }
  }
  float* d = d_texels->data();
  for (int band = 0; band < kBands; ++band) {
    const float* sum = band_sums_.data() + band * texel_floats;
    for (size_t k = 0; k < texel_floats; ++k) d[k] += sum[k];
  }
}

Image EnvironmentMap::ToImage() const {
  Image image(width, height, 3);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c)
        image.at(c, y, x) = texels[3 * (static_cast<size_t>(y) * width + x) + c];
  return image;
}

bool EnvironmentMap::FromImage(const Image& image) {
  if (image.channels() != 3 || image.width() < 2 || image.height() < 2) return false;
  if (image.width() > 65535 || image.height() > 65535) return false;  // the renderer's taps
  Reset(image.width(), image.height(), 0.0f);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c)
        texels[3 * (static_cast<size_t>(y) * width + x) + c] = image.at(c, y, x);
  return true;
}

}  // namespace mgsr
