#include "mgsr/mesh/seen_through.h"

#include <cmath>
#include <cstdint>
#include <utility>

namespace mgsr {

void SeenThroughVotes::AddView(const Camera& camera, std::vector<float> depth) {
  View v;
  v.camera = camera;
  v.depth = std::move(depth);
  v.depth.resize(static_cast<size_t>(camera.width) * camera.height, 0.0f);
  for (float& z : v.depth)
    if (!std::isfinite(z) || z < 0) z = 0;
  views_.push_back(std::move(v));
}

std::vector<bool> SeenThroughVotes::TrianglesSeenThrough(
    const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& triangles,
    double band, SeenThroughStats* stats) const {
  const int64_t n = static_cast<int64_t>(vertices.size());
  std::vector<uint8_t> remove(vertices.size(), 0);
#pragma omp parallel for schedule(dynamic, 256)
  for (int64_t i = 0; i < n; ++i) {
    int through = 0, held = 0;
    for (const View& v : views_) {
      const Eigen::Vector3d c = v.camera.WorldToCamera(vertices[i]);
      if (!(c.z() > 0)) continue;
      const Eigen::Vector2d p = v.camera.WorldToPixel(vertices[i]);
      const int w = v.camera.width, h = v.camera.height;
      if (!(p.x() >= 1 && p.y() >= 1 && p.x() < w - 1 && p.y() < h - 1)) continue;
      const int x = static_cast<int>(p.x()), y = static_cast<int>(p.y());
      const float* row = v.depth.data() + static_cast<size_t>(y) * w;
      const double z = row[x];
      if (z > 0 && std::fabs(z - c.z()) <= band) {
        ++held;
        continue;
      }
      bool all_beyond = true;  // no depth, or depth behind the vertex, at all nine pixels
      for (int dy = -1; dy <= 1 && all_beyond; ++dy) {
        const float* r = row + static_cast<ptrdiff_t>(dy) * w;
        for (int dx = -1; dx <= 1; ++dx) {
          const double d = r[x + dx];
          if (d > 0 && d <= c.z() + band) {
            all_beyond = false;
            break;
          }
        }
      }
      through += all_beyond;
    }
    remove[i] = through > held;
  }
  std::vector<bool> out(triangles.size(), false);
  SeenThroughStats s;
  s.vertices = vertices.size();
  for (uint8_t r : remove) s.removed_vertices += r;
  for (size_t t = 0; t < triangles.size(); ++t) {
    out[t] = remove[triangles[t][0]] || remove[triangles[t][1]] || remove[triangles[t][2]];
    s.removed_triangles += out[t];
  }
  if (stats != nullptr) *stats = s;
  return out;
}

}  // namespace mgsr
