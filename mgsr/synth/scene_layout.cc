#include "mgsr/synth/scene_layout.h"

#include <algorithm>
#include <cmath>

#include "mgsr/synth/solid_noise.h"

namespace mgsr {
namespace {

using synth::Smoothstep;
using synth::ValueNoise;

// The far environment's size in units of the object's radius: an open ground out to 15 (beyond
// it the sky dome's own far ground), a room 10 x 10 x 4.
constexpr double kGroundHalf = 15.0;
constexpr double kRoomHalf = 5.0;
constexpr double kRoomHeight = 4.0;

// Appends an axis-aligned quad grid: origin + i * du + j * dv for i < nu, j < nv cells, wound so
// that its normal is du x dv.
void AppendGrid(const Eigen::Vector3d& origin, const Eigen::Vector3d& du, const Eigen::Vector3d& dv,
                int nu, int nv, SurfaceMaterial material, SceneLayout* s) {
  const int base = static_cast<int>(s->mesh.vertices.size());
  for (int j = 0; j <= nv; ++j) {
    for (int i = 0; i <= nu; ++i) s->mesh.vertices.push_back(origin + i * du + j * dv);
  }
  const Eigen::Vector3d normal = du.cross(dv).normalized();
  for (int j = 0; j <= nv; ++j) {
    for (int i = 0; i <= nu; ++i) s->mesh.vertex_normals.push_back(normal);
  }
  for (int j = 0; j < nv; ++j) {
    for (int i = 0; i < nu; ++i) {
      const int a = base + j * (nu + 1) + i, b = a + 1, c = a + nu + 1, d = c + 1;
      s->mesh.triangles.emplace_back(a, b, d);
      s->mesh.triangles.emplace_back(a, d, c);
      s->materials.push_back(material);
      s->materials.push_back(material);
    }
  }
}

}  // namespace

bool ParseSceneType(const std::string& name, SceneType* type) {
  if (name == "object") {
    *type = SceneType::kObject;
  } else if (name == "outdoor") {
    *type = SceneType::kOutdoor;
  } else if (name == "indoor") {
    *type = SceneType::kIndoor;
  } else {
    return false;
  }
  return true;
}

SceneLayout MakeSceneLayout(const TriangleMesh& object, SceneType type, double region_half) {
  SceneLayout s;
  s.mesh = object;
  if (s.mesh.vertex_normals.size() != s.mesh.vertices.size()) s.mesh.ComputeVertexNormals();
  s.object_triangles = static_cast<int>(s.mesh.triangles.size());
  s.materials.assign(s.mesh.triangles.size(), SurfaceMaterial::kObject);
  double z_lo = 1e300, z_hi = -1e300;
  for (const auto& v : object.vertices) {
    z_lo = std::min(z_lo, v.z());
    z_hi = std::max(z_hi, v.z());
  }
  s.ground_z = z_lo;
  s.ground_truth = s.mesh;
  if (type == SceneType::kObject) {
    s.region = Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1));
    return s;
  }
  // Ground cells of a quarter of the region's half-size: grid lines fall on the region's sides,
  // so the ground truth is the set of cells inside it.
  const double cell = region_half / 4;
  const double half = type == SceneType::kOutdoor ? kGroundHalf : kRoomHalf;
  const int cells = 2 * static_cast<int>(std::ceil(half / cell));
  const double extent = 0.5 * cells * cell;
  const Eigen::Vector3d ground_origin(-extent, -extent, s.ground_z);
  const int ground_first = static_cast<int>(s.mesh.triangles.size());
  AppendGrid(ground_origin, Eigen::Vector3d(cell, 0, 0), Eigen::Vector3d(0, cell, 0), cells, cells,
             SurfaceMaterial::kGround, &s);
  if (type == SceneType::kIndoor) {
    // Four walls and a ceiling facing inwards, a few cells per side so the BVH stays balanced.
    const double h = kRoomHeight, e = extent;
    const int nw = 8, nh = 4;
    const double z0 = s.ground_z;
    const Eigen::Vector3d ex(2 * e / nw, 0, 0), ey(0, 2 * e / nw, 0), ez(0, 0, h / nh);
    AppendGrid({-e, -e, z0}, ez, ex, nh, nw, SurfaceMaterial::kWall, &s);      // y = -e, faces +y
    AppendGrid({-e, e, z0}, ex, ez, nw, nh, SurfaceMaterial::kWall, &s);       // y = +e, faces -y
    AppendGrid({-e, -e, z0}, ey, ez, nw, nh, SurfaceMaterial::kWall, &s);      // x = -e, faces +x
    AppendGrid({e, -e, z0}, ez, ey, nh, nw, SurfaceMaterial::kWall, &s);       // x = +e, faces -x
    AppendGrid({-e, -e, z0 + h}, ey, ex, nw, nw, SurfaceMaterial::kWall, &s);  // ceiling, faces -z
  }
  s.region = Eigen::AlignedBox3d(Eigen::Vector3d(-region_half, -region_half, s.ground_z - cell),
                                 Eigen::Vector3d(region_half, region_half, z_hi + cell));
  // Ground truth: the object and the ground cells inside the region (both triangles of a cell).
  const int object_vertices = static_cast<int>(object.vertices.size());
  std::vector<int> remap(s.mesh.vertices.size(), -1);
  for (int v = 0; v < object_vertices; ++v) remap[v] = v;
  const int ground_end = ground_first + 2 * cells * cells;
  for (int t = ground_first; t < ground_end; ++t) {
    const Eigen::Vector3i& f = s.mesh.triangles[t];
    const Eigen::Vector3d centroid =
        (s.mesh.vertices[f[0]] + s.mesh.vertices[f[1]] + s.mesh.vertices[f[2]]) / 3.0;
    if (std::abs(centroid.x()) > region_half || std::abs(centroid.y()) > region_half) continue;
    Eigen::Vector3i g;
    for (int k = 0; k < 3; ++k) {
      int& r = remap[f[k]];
      if (r < 0) {
        r = static_cast<int>(s.ground_truth.vertices.size());
        s.ground_truth.vertices.push_back(s.mesh.vertices[f[k]]);
        s.ground_truth.vertex_normals.push_back(Eigen::Vector3d::UnitZ());
      }
      g[k] = r;
    }
    s.ground_truth.triangles.push_back(g);
  }
  return s;
}

Eigen::Vector3d GroundAlbedo(const Eigen::Vector3d& p, SceneType type) {
  if (type == SceneType::kIndoor) {
    // Floor boards 0.25 wide along x, each its own shade, with grain and dark seams.
    const double across = p.y() * 4.0, board = std::floor(across), f = across - board;
    const double shade = synth::Hash3(static_cast<long>(board), 17, 5);
    const double grain = ValueNoise(Eigen::Vector3d(p.x() * 1.5, p.y() * 24.0, board));
    const double seam = Smoothstep(0.0, 0.04, std::min(f, 1 - f));
    return Eigen::Vector3d(0.42, 0.27, 0.15) * (0.65 + 0.3 * shade + 0.25 * grain) *
           (0.4 + 0.6 * seam);
  }
  // Grass and earth mixed by large-scale noise, with pebbles for fine texture.
  const double mix = ValueNoise(p * 0.7 + Eigen::Vector3d(2.3, 8.1, 0.0));
  const Eigen::Vector3d grass(0.16, 0.30, 0.08), earth(0.36, 0.28, 0.18);
  Eigen::Vector3d c = grass + (earth - grass) * Smoothstep(0.4, 0.6, mix);
  const double pebble = ValueNoise(p * 9.0 + Eigen::Vector3d(1.1, 4.4, 7.7));
  c *= 0.55 + 0.6 * Smoothstep(0.3, 0.7, pebble);
  return c;
}

Eigen::Vector3d WallAlbedo(const Eigen::Vector3d& p) {
  // Plaster with blotches and a dark stripe every unit of height: texture for matching.
  const double blotch = ValueNoise(p * 1.3 + Eigen::Vector3d(4.0, 1.0, 2.0));
  const double fine = ValueNoise(p * 13.0);
  Eigen::Vector3d c = Eigen::Vector3d(0.70, 0.66, 0.58) * (0.75 + 0.2 * blotch + 0.15 * fine);
  if (std::fmod(std::abs(p.z()) + 10.0, 1.0) < 0.06) c = Eigen::Vector3d(0.25, 0.18, 0.12);
  return c;
}

Camera SceneOrbitCamera(const SceneLayout& layout, double azimuth, double distance, int width,
                        int height, double fx, Rng* rng) {
  const Eigen::Vector3d centre = layout.region.center();
  const double h = layout.ground_z + rng->Uniform(1.3, 1.9);
  const double r = distance * (1 + rng->Uniform(-0.05, 0.05));
  const Eigen::Vector3d eye(centre.x() + r * std::cos(azimuth), centre.y() + r * std::sin(azimuth),
                            h);
  const Eigen::Vector3d target(rng->Uniform(-0.1, 0.1), rng->Uniform(-0.1, 0.1),
                               rng->Uniform(-0.1, 0.1));
  return LookAtCamera(eye, target, Eigen::Vector3d::UnitZ(), width, height, fx, fx);
}

}  // namespace mgsr
