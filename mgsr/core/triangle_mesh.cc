#include "mgsr/core/triangle_mesh.h"

#include <Eigen/Geometry>

namespace mgsr {

void TriangleMesh::ComputeVertexNormals() {
  vertex_normals.assign(vertices.size(), Eigen::Vector3d::Zero());
  for (const auto& f : triangles) {
    const Eigen::Vector3d n =
        (vertices[f[1]] - vertices[f[0]]).cross(vertices[f[2]] - vertices[f[0]]);  // 2 * area
    for (int k = 0; k < 3; ++k) vertex_normals[f[k]] += n;
  }
  for (auto& n : vertex_normals) {
    const double len = n.norm();
    if (len > 0) n /= len;
  }
}

void TriangleMesh::Append(const TriangleMesh& other) {
  const int offset = static_cast<int>(vertices.size());
  const bool had_normals = !vertex_normals.empty() || vertices.empty();
  const bool had_colors = !vertex_colors.empty() || vertices.empty();
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  for (const auto& f : other.triangles) triangles.push_back(f + Eigen::Vector3i::Constant(offset));
  if (had_normals && other.vertex_normals.size() == other.vertices.size()) {
    vertex_normals.insert(vertex_normals.end(), other.vertex_normals.begin(),
                          other.vertex_normals.end());
  } else {
    vertex_normals.clear();
  }
  if (had_colors && other.vertex_colors.size() == other.vertices.size()) {
    vertex_colors.insert(vertex_colors.end(), other.vertex_colors.begin(),
                         other.vertex_colors.end());
  } else {
    vertex_colors.clear();
  }
}

double TriangleMesh::SurfaceArea() const {
  double area = 0;
  for (const auto& f : triangles) {
    area += 0.5 * (vertices[f[1]] - vertices[f[0]]).cross(vertices[f[2]] - vertices[f[0]]).norm();
  }
  return area;
}

}  // namespace mgsr
