// Scene-level synthetic captures (mgsr_synth --scene_type outdoor|indoor): the object stands on a
// textured ground inside a far environment (an open ground under a sky dome, or a closed room),
// seen from a wide orbit at standing height. What matters for the mesh is the central region, a
// box around the object and the ground under it; its ground truth is the object plus the ground
// clipped to the box, exactly (the ground grid has lines on the box's sides).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/rng.h"
#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

enum class SceneType { kObject, kOutdoor, kIndoor };

// "object", "outdoor", "indoor"; false for anything else.
bool ParseSceneType(const std::string& name, SceneType* type);

// What a triangle of a synthetic scene is made of (how it is shaded).
enum class SurfaceMaterial : uint8_t { kObject = 0, kGround = 1, kWall = 2 };

struct SceneLayout {
  TriangleMesh mesh;                       // everything the cameras can see
  std::vector<SurfaceMaterial> materials;  // per triangle of `mesh`
  int object_triangles = 0;                // mesh triangles [0, n) are the object
  TriangleMesh ground_truth;               // the object and the ground inside `region`
  Eigen::AlignedBox3d region;              // the central region (scene units)
  double ground_z = 0;                     // height of the ground plane
};

// Puts the object (triangles first) on a ground at its lowest point, adds the ground (open, to
// `ground_half` in x and y, outdoor) or a closed room (`room_half` wide, `room_height` high,
// indoor), and the region: x, y in [-region_half, region_half], z from just under the ground to
// just over the object.
SceneLayout MakeSceneLayout(const TriangleMesh& object, SceneType type, double region_half);

// Diffuse albedo (linear) of the ground and of walls/ceiling at a point: solid textures with
// features at several scales (for matching) that differ between outdoor and indoor.
Eigen::Vector3d GroundAlbedo(const Eigen::Vector3d& p, SceneType type);
Eigen::Vector3d WallAlbedo(const Eigen::Vector3d& p);

// A camera of a scene-level orbit: azimuth around the region's centre at `distance` (horizontal),
// at a standing height of 1.3-1.9 units over the ground, looking at the object's centre (jittered
// a little).
Camera SceneOrbitCamera(const SceneLayout& layout, double azimuth, double distance, int width,
                        int height, double fx, Rng* rng);

}  // namespace mgsr
