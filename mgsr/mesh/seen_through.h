// Free space from the fused views: the parts of a fused mesh that the views see through.
//
// A TSDF only moves towards a surface where a view has depth; a view that renders nothing at a
// pixel (alpha or mask below the threshold), or a surface well behind a point, says nothing to it
// about the space in front. So a sheet of primitives that a few views show as a surface (painted in
// the backdrop's colour, or fitted to one view's light) stays in the mesh even when every other
// view looks straight through it. This counts, for every vertex of the extracted mesh, the views
// that see through it against those whose depth holds it, and removes the vertices that more views
// see through than hold (docs/geometry.md, "Free space").
//
// A view sees through a vertex when the vertex lies in front of it, inside its frame, and at its
// pixel and the eight around it the view has no depth or depth beyond the vertex by more than the
// support band (the TSDF's truncation): one pixel of slack, so that a surface's own outline (where
// a neighbouring view's render ends a fraction of a pixel early) does not count against it. A view
// holds a vertex when its depth at the vertex's pixel lies within the band.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "mgsr/core/camera.h"

namespace mgsr {

struct SeenThroughStats {
  size_t vertices = 0, removed_vertices = 0, removed_triangles = 0;
};

class SeenThroughVotes {
 public:
  // Keeps one view's depth (camera-space z per pixel, row-major, camera.width x camera.height;
  // 0 or non-finite: nothing there). Four bytes a pixel per view are held until the votes are
  // counted.
  void AddView(const Camera& camera, std::vector<float> depth);

  // The triangles to remove: those with a vertex that more views see through than hold, with
  // `band` the support band in scene units.
  std::vector<bool> TrianglesSeenThrough(const std::vector<Eigen::Vector3d>& vertices,
                                         const std::vector<Eigen::Vector3i>& triangles, double band,
                                         SeenThroughStats* stats = nullptr) const;

 private:
  struct View {
    Camera camera;
    std::vector<float> depth;
  };
  std::vector<View> views_;
};

}  // namespace mgsr
