// The region a mesh is fused in (docs/design.md): scene-level captures see ground, walls and
// sky far beyond what they were taken of, and fusing all of it makes a mesh of the background.
// The region is a box: given by the user, read from a file (gt/region.json of mgsr_synth), or
// found from the cameras as the volume most of their view frusta share.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

// The bounding box of the points that at least `min_share` of the cameras see (in front, inside
// the image), sampled on a grid^3 lattice spanning the median camera distance around the point the
// cameras look at (LookAtCenter), grown by one lattice step. Empty when no lattice point qualifies
// (e.g. cameras that share no view).
Eigen::AlignedBox3d RegionFromCameras(const std::vector<Camera>& cameras, double min_share = 0.5,
                                      int grid = 64);

// "x0,y0,z0,x1,y1,z1" (min and max corners) or the path of a JSON file with "min" and "max"
// arrays. Errors name the text or the file and what is wrong.
Status ParseRegion(const std::string& text, Eigen::AlignedBox3d* region);

// "[x0, y0, z0] .. [x1, y1, z1]" for logs.
std::string RegionToString(const Eigen::AlignedBox3d& region);

// Per triangle: whether one of its vertices lies outside `region`.
std::vector<bool> TrianglesOutside(const Eigen::AlignedBox3d& region,
                                   const std::vector<Eigen::Vector3d>& vertices,
                                   const std::vector<Eigen::Vector3i>& triangles);

// Removes the triangles with a vertex outside `region` and the vertices no triangle uses.
void CropMeshToRegion(const Eigen::AlignedBox3d& region, TriangleMesh* mesh);

}  // namespace mgsr
