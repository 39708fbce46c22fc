#include "mgsr/synth/shapes.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>

namespace mgsr {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Splits every triangle into four, projecting new vertices with `project`.
template <typename Project>
void Subdivide(TriangleMesh* mesh, Project project) {
  std::map<std::pair<int, int>, int> midpoint;
  auto mid = [&](int a, int b) {
    const auto key = std::minmax(a, b);
    auto it = midpoint.find(key);
    if (it != midpoint.end()) return it->second;
    const int id = static_cast<int>(mesh->vertices.size());
    mesh->vertices.push_back(project(0.5 * (mesh->vertices[a] + mesh->vertices[b])));
    midpoint[key] = id;
    return id;
  };
  std::vector<Eigen::Vector3i> tris;
  tris.reserve(mesh->triangles.size() * 4);
  for (const auto& f : mesh->triangles) {
    const int ab = mid(f[0], f[1]), bc = mid(f[1], f[2]), ca = mid(f[2], f[0]);
    tris.emplace_back(f[0], ab, ca);
    tris.emplace_back(f[1], bc, ab);
    tris.emplace_back(f[2], ca, bc);
    tris.emplace_back(ab, bc, ca);
  }
  mesh->triangles = std::move(tris);
}

TriangleMesh UnitIcoSphere(int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  TriangleMesh m;
  const double v[12][3] = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                           {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                           {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (const auto& p : v) m.vertices.push_back(Eigen::Vector3d(p[0], p[1], p[2]).normalized());
  const int f[20][3] = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                        {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                        {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                        {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (const auto& tri : f) m.triangles.emplace_back(tri[0], tri[1], tri[2]);
  for (int s = 0; s < subdivisions; ++s) {
    Subdivide(&m, [](const Eigen::Vector3d& p) { return p.normalized(); });
  }
  return m;
}

}  // namespace

TriangleMesh MakeIcoSphere(double radius, int subdivisions) {
  TriangleMesh m = UnitIcoSphere(subdivisions);
  for (auto& p : m.vertices) p *= radius;
  m.ComputeVertexNormals();
  return m;
}

TriangleMesh MakeTorus(double R, double r, int nu, int nv) {
  TriangleMesh m;
  for (int i = 0; i < nu; ++i) {
    const double u = 2 * kPi * i / nu;
    for (int j = 0; j < nv; ++j) {
      const double v = 2 * kPi * j / nv;
      m.vertices.emplace_back((R + r * std::cos(v)) * std::cos(u),
                              (R + r * std::cos(v)) * std::sin(u), r * std::sin(v));
    }
  }
  auto id = [&](int i, int j) { return ((i + nu) % nu) * nv + (j + nv) % nv; };
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      m.triangles.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      m.triangles.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  }
  m.ComputeVertexNormals();
  return m;
}

TriangleMesh MakeRoundedBox(double b, double r, int n) {
  // A subdivided cube, each surface point pushed to distance r from the inner box of half-size b -
  // r.
  TriangleMesh m;
  const double inner = b - r;
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign : {-1, 1}) {
      const int base = static_cast<int>(m.vertices.size());
      const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
      for (int i = 0; i <= n; ++i) {
        for (int j = 0; j <= n; ++j) {
          Eigen::Vector3d p;
          p[axis] = sign * b;
          p[a1] = -b + 2 * b * i / n;
          p[a2] = -b + 2 * b * j / n;
          const Eigen::Vector3d q = p.cwiseMax(-inner).cwiseMin(inner);
          const Eigen::Vector3d d = p - q;
          m.vertices.push_back(d.norm() > 0 ? Eigen::Vector3d(q + r * d.normalized()) : p);
        }
      }
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          const int v00 = base + i * (n + 1) + j, v10 = v00 + n + 1, v01 = v00 + 1, v11 = v10 + 1;
          // (a1, a2, axis) is right-handed, so (a1 x a2) points along +axis.
          if (sign > 0) {
            m.triangles.emplace_back(v00, v10, v11);
            m.triangles.emplace_back(v00, v11, v01);
          } else {
            m.triangles.emplace_back(v00, v11, v10);
            m.triangles.emplace_back(v00, v01, v11);
          }
        }
      }
    }
  }
  // Weld the duplicated edge vertices so the mesh is closed.
  std::map<std::tuple<long, long, long>, int> index;
  std::vector<int> remap(m.vertices.size());
  std::vector<Eigen::Vector3d> unique;
  for (size_t i = 0; i < m.vertices.size(); ++i) {
    const auto key =
        std::make_tuple(std::lround(m.vertices[i].x() * 1e6), std::lround(m.vertices[i].y() * 1e6),
                        std::lround(m.vertices[i].z() * 1e6));
    auto it = index.find(key);
    if (it == index.end()) {
      it = index.emplace(key, static_cast<int>(unique.size())).first;
      unique.push_back(m.vertices[i]);
    }
    remap[i] = it->second;
  }
  m.vertices = unique;
  for (auto& f : m.triangles) f = Eigen::Vector3i(remap[f[0]], remap[f[1]], remap[f[2]]);
  m.ComputeVertexNormals();
  return m;
}

TriangleMesh MakeDentedSphereWithRod(int subdivisions) {
  const Eigen::Vector3d dents[3] = {Eigen::Vector3d(1, 0.3, 0.2).normalized(),
                                    Eigen::Vector3d(-0.4, 1, -0.3).normalized(),
                                    Eigen::Vector3d(-0.5, -0.6, 0.6).normalized()};
  auto radius = [&](const Eigen::Vector3d& d) {
    double r = 0.75;
    for (const auto& c : dents) r -= 0.22 * std::pow(std::max(0.0, d.dot(c)), 12.0);
    return r;
  };
  TriangleMesh body = UnitIcoSphere(subdivisions);
  for (auto& p : body.vertices) p *= radius(p);
  body.ComputeVertexNormals();

  // Thin rod (radius 0.04) along a direction without dents, from just inside the body to radius 1.
  const Eigen::Vector3d axis = Eigen::Vector3d(0.2, -0.3, -1).normalized();
  const double start = radius(axis) - 0.02, end = 0.98, rr = 0.04;
  Eigen::Vector3d e1 = axis.unitOrthogonal(), e2 = axis.cross(e1);
  TriangleMesh rod;
  const int seg = 12 + 4 * subdivisions, rings = 8;
  for (int k = 0; k <= rings; ++k) {
    const double s = start + (end - start) * k / rings;
    for (int j = 0; j < seg; ++j) {
      const double a = 2 * kPi * j / seg;
      rod.vertices.push_back(s * axis + rr * (std::cos(a) * e1 + std::sin(a) * e2));
    }
  }
  for (int k = 0; k < rings; ++k) {
    for (int j = 0; j < seg; ++j) {
      const int a = k * seg + j, b = k * seg + (j + 1) % seg, c = a + seg, d = b + seg;
      rod.triangles.emplace_back(a, b, d);
      rod.triangles.emplace_back(a, d, c);
    }
  }
  // Cap at the far end.
  const int tip = static_cast<int>(rod.vertices.size());
  rod.vertices.push_back(end * axis);
  for (int j = 0; j < seg; ++j)
    rod.triangles.emplace_back(rings * seg + j, rings * seg + (j + 1) % seg, tip);
  rod.ComputeVertexNormals();
  body.Append(rod);
  return body;
}

std::vector<std::string> ShapeNames() {
  return {"sphere", "torus", "rounded_box", "dented", "gear", "slot", "knot", "wall"};
}

bool ShapeHasSharpEdges(const std::string& name) {
  return name == "gear" || name == "slot" || name == "wall";
}

bool MakeShape(const std::string& name, int detail, TriangleMesh* mesh) {
  detail = std::max(0, std::min(2, detail));
  if (name == "sphere")
    *mesh = MakeIcoSphere(0.8, 3 + detail);
  else if (name == "torus")
    *mesh = MakeTorus(0.65, 0.3, 48 << detail, 24 << detail);
  else if (name == "rounded_box")
    *mesh = MakeRoundedBox(0.55, 0.15, 12 << detail);
  else if (name == "dented")
    *mesh = MakeDentedSphereWithRod(3 + detail);
  else if (name == "gear")
    *mesh = MakeGear(14, 16 << detail);
  else if (name == "slot")
    *mesh = MakeSlottedBlock(4 << detail);
  else if (name == "knot")
    *mesh = MakeTrefoilKnot(192 << detail, 16 << detail);
  else if (name == "wall")
    *mesh = MakePrintedWall();
  else
    return false;
  return true;
}

}  // namespace mgsr
