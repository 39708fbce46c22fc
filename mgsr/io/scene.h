// Scene: what the solver trains on, read from a COLMAP workspace, a nerfstudio / instant-ngp
// transforms.json or a Blender/NeRF-synthetic folder. Photos through a distorted lens are
// resampled once to pinhole images (mgsr/io/undistort.h); the solver sees pinhole cameras only.
//
// COLMAP workspace:  images/, optional masks/<stem>.png|jpg (or <name>.png), sparse/0/ or sparse/
//                    (binary or text; every camera model but FOV and THIN_PRISM_FISHEYE), optional
//                    split.txt / test.txt listing test image names; or the `colmap
//                    image_undistorter` output (dense/images + dense/sparse/), given as the
//                    workspace or as the dense/ folder itself.
// nerfstudio:        one transforms.json: global or per-frame fl_x fl_y cx cy w h, camera_model
//                    PINHOLE / OPENCV / OPENCV_FISHEYE with k1..k4 p1 p2, train_filenames /
//                    test_filenames (else every test_every-th frame), ply_file_path, mask_path.
// Blender folder:    transforms_train.json, transforms_test.json, images referenced by file_path
//                    (RGBA), masks from the frame's mask_path, masks/<basename>.png, or alpha.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/core/status.h"
#include "mgsr/io/undistort.h"

namespace mgsr {

struct View {
  std::string name;  // image file name (as listed in the model / json)
  Camera camera;
  Image image;  // RGB in [0, 1]; straight colour where alpha exists (not composited)
  Image alpha;  // 1 channel, empty when the file had no alpha
  Image mask;   // 1 channel in [0, 1] (foreground = 1), empty when the scene has no masks
  bool is_test = false;
  int photo_width = 0, photo_height = 0;  // the photo's own size (before downscale and caps)
};

struct SceneOptions {
  int downscale = 1;  // divide the resolution by this factor
  // Then cap the long side (0 = no cap), as 3DGS's loader does above 1.6k, and the width.
  int max_size = 1600;
  int max_width = 0;
  int test_every = 8;  // without a split file, every Nth image (by name) is a test view; 0 = none
  bool load_images = true;     // false: cameras and points only
  int random_points = 100000;  // points drawn when the model has none
  // Unbounded captures: this many more points on a sphere far around the cameras (AddFarPoints),
  // for what lies beyond the SfM points (far background, sky).
  int far_points = 0;
  double far_radius = 10;  // the sphere's radius in scene extents
  uint64_t seed = 0;
};

struct Scene {
  std::string root;
  std::string source;  // "colmap", "nerfstudio" or "blender"
  std::vector<View> views;
  std::vector<Eigen::Vector3f> points;        // initialisation points
  std::vector<Eigen::Vector3f> point_colors;  // in [0, 1]
  bool random_points = false;                 // true when the points were drawn, not read
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double extent = 1.0;  // 1.1 x max distance of training cameras from their centroid (ref. 1.8)
  std::vector<std::string> warnings;
  // What the loader did to the photos that a user should know (lenses undistorted, sizes capped).
  std::vector<std::string> notes;

  std::vector<int> TrainIndices() const;
  std::vector<int> TestIndices() const;
  bool has_masks() const;
};

// The view's image composited onto a uniform background with its alpha (the image itself when it
// has no alpha): the ground truth a branch rendering on that background is compared with.
Image CompositeOnBackground(const View& view, float background);

// What makes a loaded scene trainable, checked before any training (a scene that fails one of
// these trained and then failed at fusion, with a message about voxels or empty depth): at least
// two training views, images of at least 16 x 16 pixels, and (for points that were read, not
// drawn) at least four points in front of and inside the frames of two training cameras. The
// error names the scene and what is wrong with it.
Status CheckTrainable(const Scene& scene);

// Detects the layout and loads. Every error names the file and the problem.
Status LoadScene(const std::string& path, const SceneOptions& options, Scene* scene);

// Loaders for one layout each (LoadScene dispatches to them).
Status LoadColmapScene(const std::string& root, const SceneOptions& options, Scene* scene);
Status LoadBlenderScene(const std::string& root, const SceneOptions& options, Scene* scene);

// Shared steps, exposed for the loaders and tests.
// Reads an image (and its mask, when mask_path is non-empty), checks the size against the camera,
// splits off alpha, resamples a distorted photo to its pinhole image (`undistortion`, when given:
// the view's camera already has the pinhole intrinsics; its maps are made here when it has none)
// and resizes image, mask and camera per the options.
Status LoadViewImages(const std::string& image_path, const std::string& mask_path,
                      const SceneOptions& options, View* view,
                      const Undistortion* undistortion = nullptr);
// Centre and extent from the training cameras (reference getNerfppNorm).
void ComputeSceneExtent(Scene* scene);
// Uniform points inside the volume that all training cameras see (relaxed to most cameras if
// that volume is too small to sample); used when the model has no points.
void SampleRandomPoints(int count, uint64_t seed, Scene* scene);
// Adds `count` grey points uniformly on the sphere of `radius_scale` x scene->extent around
// scene->center (an initialisation of the far background that SfM points leave out).
void AddFarPoints(int count, double radius_scale, uint64_t seed, Scene* scene);

}  // namespace mgsr
