#include "mgsr/model/environment_map.h"

#include <algorithm>
#include <cmath>

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

const std::vector<EnvironmentTaps>& EnvironmentRenderer::TapsFor(const EnvironmentMap& map,
                                                                 const Camera& camera) {
  const size_t n = static_cast<size_t>(camera.width) * camera.height;
  if (taps_.size() == n && camera_ == camera && map_width_ == map.width &&
      map_height_ == map.height)
    return taps_;
  taps_.resize(n);
  const Eigen::Matrix3d Rt = camera.R.transpose();
#pragma omp parallel for schedule(static)
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const Eigen::Vector3d d = (Rt * camera.PixelToRay(x + 0.5, y + 0.5)).normalized();
      taps_[static_cast<size_t>(y) * camera.width + x] = map.Taps(d);
    }
  }
  camera_ = camera;
  map_width_ = map.width;
  map_height_ = map.height;
  return taps_;
}

void EnvironmentRenderer::Render(const EnvironmentMap& map, const Camera& camera, Image* out) {
  const std::vector<EnvironmentTaps>& taps = TapsFor(map, camera);
  if (out->width() != camera.width || out->height() != camera.height || out->channels() != 3)
    *out = Image(camera.width, camera.height, 3);
  const size_t n = taps.size();
  for (size_t i = 0; i < n; ++i) {
    float rgb[3];
    map.Lookup(taps[i], map.texels, rgb);
    for (int c = 0; c < 3; ++c) out->plane(c)[i] = rgb[c];
  }
}

void EnvironmentRenderer::Backward(const EnvironmentMap& map, const Camera& camera,
                                   const Image& grad, std::vector<float>* d_texels) {
  const std::vector<EnvironmentTaps>& taps = TapsFor(map, camera);
  d_texels->resize(map.texels.size(), 0.0f);
  const size_t n = taps.size();
  for (size_t i = 0; i < n; ++i) {
    const EnvironmentTaps& t = taps[i];
    for (int c = 0; c < 3; ++c) {
      const float g = grad.plane(c)[i];
      if (g == 0) continue;
      for (int k = 0; k < 4; ++k)
        (*d_texels)[3 * t.texel[k] + c] += static_cast<float>(t.weight[k]) * g;
    }
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
  Reset(image.width(), image.height(), 0.0f);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < 3; ++c)
        texels[3 * (static_cast<size_t>(y) * width + x) + c] = image.at(c, y, x);
  return true;
}

}  // namespace mgsr
