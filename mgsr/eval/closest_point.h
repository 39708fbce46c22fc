// Exact closest point on a triangle mesh (docs/design.md): the query behind the exact
// geometry metric. Candidates come from a kd-tree over dense samples that remember their triangle;
// the search radius is widened by the samples' covering radius, so the answer is the true closest
// point on the mesh's triangles, not an approximation by its samples.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

// Closest point to `p` on triangle (a, b, c) (Ericson, Real-Time Collision Detection, 5.1.5).
// Degenerate triangles give a point on their segment or vertex.
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c);

struct ClosestPoint {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  double distance = 0;
  int triangle = -1;  // -1: the mesh has no triangle
};

class TriangleClosestPoint {
 public:
  // Indexes the triangles of `mesh` (kept by reference: it must outlive this object). Zero-area
  // triangles are skipped (they have no surface to be closest to that their neighbours lack).
  explicit TriangleClosestPoint(const TriangleMesh& mesh);
  ~TriangleClosestPoint();

  bool empty() const;
  // The exact closest point on the mesh's triangles.
  ClosestPoint Query(const Eigen::Vector3d& p) const;
  // How far beyond the nearest sample's triangle a query searches: the sampled triangles'
  // covering radius. Oversized triangles (a stray vertex far away) are tested directly and do not
  // widen it, so one of them cannot make every query visit every sample.
  double search_slack() const;
  // Unit face normal of a triangle, oriented like the vertex normals when the mesh has them (so a
  // mesh whose winding disagrees with its normals still gets outward normals), else by winding.
  const Eigen::Vector3d& FaceNormal(int triangle) const { return face_normals_[triangle]; }

 private:
  struct Index;
  const TriangleMesh& mesh_;
  std::vector<Eigen::Vector3d> face_normals_;
  std::unique_ptr<Index> index_;
};

}  // namespace mgsr
