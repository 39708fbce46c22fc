// TriangleMesh: vertices, triangles and optional per-vertex normals and colours. Used for ground
// truth (synthetic scenes), TSDF output and evaluation; not a hot-loop type.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace mgsr {

struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3i> triangles;
  std::vector<Eigen::Vector3d> vertex_normals;  // empty or one per vertex
  std::vector<Eigen::Vector3f> vertex_colors;   // empty or one per vertex, in [0, 1]

  bool empty() const { return vertices.empty() || triangles.empty(); }
  // Area-weighted vertex normals from the triangles (counter-clockwise = outward).
  void ComputeVertexNormals();
  // Appends another mesh, offsetting its indices.
  void Append(const TriangleMesh& other);
  double SurfaceArea() const;
};

}  // namespace mgsr
