// Solid (3-D) textures for synthetic scenes: hash-based value noise evaluated at world points, so
// a surface's texture is the same from every view.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>

namespace mgsr::synth {

inline double Smoothstep(double a, double b, double x) {
  const double t = std::min(1.0, std::max(0.0, (x - a) / (b - a)));
  return t * t * (3 - 2 * t);
}

// A hash of an integer lattice point in [0, 1].
inline double Hash3(long x, long y, long z) {
  uint64_t h = static_cast<uint64_t>(x) * 0x8DA6B343ull ^ static_cast<uint64_t>(y) * 0xD8163841ull ^
               static_cast<uint64_t>(z) * 0xCB1AB31Full;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 32;
  return (h & 0xFFFFFF) / static_cast<double>(0xFFFFFF);
}

// Value noise in [0, 1]: the lattice hashes blended with smoothstep weights.
inline double ValueNoise(const Eigen::Vector3d& p) {
  const Eigen::Vector3d f(std::floor(p.x()), std::floor(p.y()), std::floor(p.z()));
  const Eigen::Vector3d t = p - f;
  const Eigen::Vector3d s(Smoothstep(0, 1, t.x()), Smoothstep(0, 1, t.y()),
                          Smoothstep(0, 1, t.z()));
  const long x = static_cast<long>(f.x()), y = static_cast<long>(f.y()),
             z = static_cast<long>(f.z());
  double v = 0;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const double w = (dx ? s.x() : 1 - s.x()) * (dy ? s.y() : 1 - s.y()) * (dz ? s.z() : 1 - s.z());
    v += w * Hash3(x + dx, y + dy, z + dz);
  }
  return v;
}

}  // namespace mgsr::synth
