#include "mgsr/eval/normal_error.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "mgsr/synth/ray_caster.h"

namespace mgsr {
namespace {

constexpr double kRadToDeg = 57.29577951308232;

// World direction of the ray through the centre of pixel (x, y).
Eigen::Vector3d PixelDirection(const Camera& cam, int x, int y) {
  return cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5);
}

}  // namespace

Image RenderExactNormal(const RayCaster& caster, const Camera& cam) {
  Image out(cam.width, cam.height, 3);
  const Eigen::Vector3d origin = cam.Center();
#pragma omp parallel for schedule(dynamic, 8)
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const Eigen::Vector3d d = PixelDirection(cam, x, y);
      RayHit hit;
      if (!caster.Intersect(origin, d, 1e-9, 1e9, &hit)) continue;
      Eigen::Vector3d n = caster.FaceNormal(hit.triangle);
      if (n.dot(d) > 0) n = -n;
      for (int c = 0; c < 3; ++c) out.at(c, y, x) = static_cast<float>(n[c]);
    }
  }
  return out;
}

void NormalErrorAccumulator::Add(const Image& rendered, const Image& truth, const Image* mask,
                                 const Camera& cam) {
  for (int y = 0; y < truth.height(); ++y) {
    for (int x = 0; x < truth.width(); ++x) {
      if (mask != nullptr && mask->at(0, y, x) < 0.5f) continue;
      const Eigen::Vector3d t(truth.at(0, y, x), truth.at(1, y, x), truth.at(2, y, x));
      const Eigen::Vector3d r(rendered.at(0, y, x), rendered.at(1, y, x), rendered.at(2, y, x));
      const double tn = t.norm(), rn = r.norm();
      if (!(tn > 0.5) || !(rn > 1e-6) || !std::isfinite(rn)) continue;
      const Eigen::Vector3d d = PixelDirection(cam, x, y);
      Eigen::Vector3d a = t / tn, b = r / rn;
      if (a.dot(d) > 0) a = -a;
      if (b.dot(d) > 0) b = -b;
      const double c = std::max(-1.0, std::min(1.0, a.dot(b)));
      angles_deg_.push_back(static_cast<float>(std::acos(c) * kRadToDeg));
    }
  }
}

NormalErrorStats NormalErrorAccumulator::Finish() const {
  NormalErrorStats s;
  s.pixels = angles_deg_.size();
  if (s.pixels == 0) return s;
  double sum = 0;
  size_t beyond = 0;
  for (float a : angles_deg_) {
    sum += a;
    beyond += a > 10.0f;
  }
  s.mean_deg = sum / s.pixels;
  s.share_beyond_10deg = static_cast<double>(beyond) / s.pixels;
  std::vector<float> sorted = angles_deg_;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  s.median_deg = sorted[sorted.size() / 2];
  return s;
}

}  // namespace mgsr
