// Synthetic scenes with exact ground truth: a built-in mesh ray-cast from cameras on a sphere, with
// a textured diffuse surface, strong specular highlights and optional mirror-like reflection of a
// simple environment, under light that changes per view (direction, intensity, colour, environment
// strength, exposure). Written as a COLMAP workspace and a Blender folder at once (they share
// images/). Scene-level captures (scene_type outdoor / indoor, see scene_layout.h) put the object
// on a textured ground in a far environment, seen from standing height on a wide orbit, without
// masks; their ground truth is the central region's mesh.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/core/lens.h"
#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"
#include "mgsr/synth/scene_layout.h"

namespace mgsr {

class RayCaster;
struct RayHit;

struct SynthOptions {
  std::string scene_type = "object";  // object | outdoor | indoor (ParseSceneType)
  std::string shape = "sphere";       // see ShapeNames()
  // A mesh file (OBJ, PLY or glb) to render instead of `shape`: centred on its bounding box and
  // scaled so that its farthest vertex lies at radius 1, as the built-in shapes (NormaliseMesh).
  std::string mesh_path;
  // The object's diffuse texture: "noise" (two colours and speckles, low contrast) or "print"
  // (a high-contrast printed pattern: geometry that copies texture shows in its normals).
  std::string texture = "noise";
  int detail = 1;  // mesh detail 0..2
  int num_views = 48;
  int width = 128, height = 128;
  double fov_x = 0.6911112;  // radians (as the shared suzanne scene)
  double distance = 3.5;     // camera distance from the origin
  double min_elevation_deg = -20, max_elevation_deg = 70;
  int test_every = 8;  // views i with i % test_every == 0 are test views (0: none)
  uint64_t seed = 1;
  int supersampling = 2;  // samples per pixel per axis (anti-aliased edges and alpha)
  double specular = 0.7;  // highlight strength (Blinn-Phong)
  double shininess = 80;
  double mirror = 0.0;  // 0..1: weight of the reflected environment (Fresnel-scaled)
  bool varying_light = true;
  double exposure_stops = 1.0;    // per-view exposure drawn from [-s, +s] when the light varies
  int num_points = 2000;          // surface points written to points3D (seen by >= 2 train views)
  bool write_text_model = false;  // sparse/0 as text instead of binary
  bool constant_light_copy = false;  // also render images_constant/ under one fixed light
  // Noisy poses: the cameras written to the model (COLMAP and json) are turned by about this many
  // degrees (rms, random axes) and moved by this fraction of the camera distance (rms); the images
  // are rendered with the true cameras.
  double pose_noise_deg = 0.0, pose_noise_rel = 0.0;
  // false: no masks/ and no alpha; RGB photos with the object on a grey background. Scene-level
  // captures never have masks (their photos are RGB whatever this says).
  bool masks = true;
  // The photos' lens: "pinhole", "opencv" (barrel distortion with tangential terms) or "fisheye"
  // (OpenCV's equidistant model), rendered exactly (a ray per distorted pixel). Distorted scenes
  // carry their lens in the COLMAP model (OPENCV / OPENCV_FISHEYE) and in one nerfstudio
  // transforms.json instead of the Blender pair, and have no gt/depth or gt/normal maps (those
  // would be in the distorted frame; gt/mesh.ply remains).
  std::string lens = "pinhole";
  // Each view its own focal length (x0.85..1.15, seeded): per-frame intrinsics in the json, one
  // camera per view in the COLMAP model.
  bool per_frame_focal = false;
  // Scene-level: half the side of the central region's square (the object has radius 1); the
  // cameras stand `distance` away from its centre, horizontally.
  double region_half = 2.0;

  Status Validate() const;
};

struct ViewLight {
  Eigen::Vector3d direction{0, 0, 1};  // unit, towards the light
  double intensity = 1.0;
  Eigen::Vector3d color{1, 1, 1};
  double environment = 1.0;  // environment (ambient and reflection) strength
  double exposure_stops = 0.0;
};

// The lens a synthetic scene's photos are taken through (SynthOptions::lens), for `camera`'s
// intrinsics.
Lens SyntheticLens(const std::string& lens, const Camera& camera);

struct SyntheticScene {
  SceneType type = SceneType::kObject;
  // layout.mesh: everything the cameras see; layout.ground_truth: what the mesh is measured
  // against (the object, or the central region's object and ground).
  SceneLayout layout;
  std::vector<Camera> cameras;
  std::vector<std::string> names;  // image file names, e.g. v000.png
  std::vector<bool> is_test;
  std::vector<ViewLight> lights;
};

// Centres a mesh on its bounding box and scales it so that its farthest vertex lies at `radius`.
void NormaliseMesh(TriangleMesh* mesh, double radius);

// The object mesh of `options`: the file at mesh_path (normalised, with vertex normals when it has
// none) or the built-in shape.
Status MakeObjectMesh(const SynthOptions& options, TriangleMesh* mesh);

// Builds the mesh, cameras and lights (no rendering).
Status MakeSyntheticScene(const SynthOptions& options, SyntheticScene* scene);

// Renders views of a scene: ray casters over everything (primary and reflection rays) and over the
// object alone (shadows: the light of a room is inside it). Keeps a reference to `scene`, which
// must outlive it.
class SyntheticRenderer {
 public:
  SyntheticRenderer(const SyntheticScene& scene, const SynthOptions& options);
  ~SyntheticRenderer();
  // RGBA (sRGB, straight alpha; scene-level: the sky where nothing is hit, alpha 1), z-depth at
  // pixel centres (0 = nothing hit) and world-space unit normals (0 = nothing hit).
  // With a lens, each pixel's rays go through it (the camera's intrinsics are the lens's).
  void Render(const Camera& camera, const ViewLight& light, Image* rgba, Image* depth,
              Image* normal, const Lens* lens = nullptr) const;
  const RayCaster& caster() const { return *caster_; }

 private:
  Eigen::Vector3d ShadeHit(const RayHit& hit, const Eigen::Vector3d& origin,
                           const Eigen::Vector3d& direction, const ViewLight& light,
                           bool reflections) const;
  const SyntheticScene& scene_;
  const SynthOptions options_;
  TriangleMesh object_;
  std::unique_ptr<RayCaster> caster_, shadow_caster_;
};

// Writes the whole scene into `out_dir` (created). Files: images/, masks/ (unless !masks),
// sparse/0/, split.txt,
// transforms_{train,test}.json, points3d.ply, lights.json, gt/mesh.ply (layout.ground_truth),
// gt/region.json (scene-level: the region's box), gt/depth/*.pfm,
// gt/normal/*.pfm and, if asked, images_constant/.
Status WriteSyntheticScene(const SynthOptions& options, const std::string& out_dir);

}  // namespace mgsr
