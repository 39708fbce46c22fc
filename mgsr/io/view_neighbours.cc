#include "mgsr/io/view_neighbours.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace mgsr {
namespace {

constexpr double kDegToRad = 0.017453292519943295;

bool Sees(const Camera& cam, const Eigen::Vector3d& X) {
  const Eigen::Vector3d c = cam.WorldToCamera(X);
  if (!(c.z() > 1e-9)) return false;
  const Eigen::Vector2d p = cam.CameraToPixel(c);
  return p.x() >= 0 && p.y() >= 0 && p.x() <= cam.width && p.y() <= cam.height;
}

}  // namespace

std::vector<std::vector<int>> SelectNeighbours(const Scene& scene,
                                               const NeighbourOptions& options) {
  const int n = static_cast<int>(scene.views.size());
  std::vector<std::vector<int>> out(n);
  if (options.count <= 0) return out;
  const std::vector<int> train = scene.TrainIndices();
  std::vector<Eigen::Vector3d> points;
  const size_t total = scene.points.size();
  const size_t step =
      std::max<size_t>(1, (total + options.max_points - 1) / std::max(1, options.max_points));
  for (size_t i = 0; i < total; i += step) points.push_back(scene.points[i].cast<double>());
  if (points.empty()) points.push_back(scene.center);
  // visible[v][p]: view v sees point p.
  std::vector<std::vector<char>> visible(n, std::vector<char>(points.size(), 0));
  for (int v = 0; v < n; ++v)
    for (size_t p = 0; p < points.size(); ++p)
      visible[v][p] = Sees(scene.views[v].camera, points[p]) ? 1 : 0;
  const double lo = options.min_angle_deg * kDegToRad, hi = options.max_angle_deg * kDegToRad;
  const double mid = options.preferred_angle_deg * kDegToRad;
  for (int v = 0; v < n; ++v) {
    const Eigen::Vector3d cv = scene.views[v].camera.Center();
    std::vector<std::pair<double, int>> scored;
    for (int u : train) {
      if (u == v) continue;
      const Eigen::Vector3d cu = scene.views[u].camera.Center();
      double score = 0;
      for (size_t p = 0; p < points.size(); ++p) {
        if (!visible[v][p] || !visible[u][p]) continue;
        const Eigen::Vector3d a = (cv - points[p]).normalized(), b = (cu - points[p]).normalized();
        const double angle = std::acos(std::max(-1.0, std::min(1.0, a.dot(b))));
        if (angle < lo || angle > hi) continue;
        // A Gaussian around the preferred angle, wider on the far side (MVSNet's view score).
        const double sigma = angle < mid ? 0.5 * mid : 2.0 * mid;
        score += std::exp(-(angle - mid) * (angle - mid) / (2 * sigma * sigma));
      }
      if (score > 0) scored.emplace_back(score, u);
    }
    // Best first; ties by view index, so the choice does not depend on anything but the scene.
    std::sort(scored.begin(), scored.end(), [](const auto& x, const auto& y) {
      return x.first != y.first ? x.first > y.first : x.second < y.second;
    });
    for (size_t k = 0; k < scored.size() && static_cast<int>(k) < options.count; ++k)
      out[v].push_back(scored[k].second);
  }
  return out;
}

}  // namespace mgsr
