#include "mgsr/io/scene.h"

#include <algorithm>
#include <cmath>

#include "mgsr/core/rng.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"

namespace mgsr {

std::vector<int> Scene::TrainIndices() const {
  std::vector<int> idx;
  for (int i = 0; i < static_cast<int>(views.size()); ++i) {
    if (!views[i].is_test) idx.push_back(i);
  }
  return idx;
}

std::vector<int> Scene::TestIndices() const {
  std::vector<int> idx;
  for (int i = 0; i < static_cast<int>(views.size()); ++i) {
    if (views[i].is_test) idx.push_back(i);
  }
  return idx;
}

bool Scene::has_masks() const {
  for (const View& v : views) {
    if (v.mask.empty()) return false;
  }
  return !views.empty();
}

Image CompositeOnBackground(const View& v, float background) {
  Image out = v.image;
  if (v.alpha.empty()) return out;
  for (int c = 0; c < 3; ++c) {
    for (size_t i = 0; i < out.plane_size(); ++i) {
      const float a = v.alpha.plane(0)[i];
      out.plane(c)[i] = out.plane(c)[i] * a + background * (1 - a);
    }
  }
  return out;
}

Status LoadScene(const std::string& path, const SceneOptions& options, Scene* scene) {
  if (options.downscale < 1) return Status::Error("--downscale must be >= 1");
  if (options.max_width < 0) return Status::Error("--max_width must be >= 0");
  if (!DirectoryExists(path)) return Status::Error(path + ": scene folder does not exist");
  const bool colmap = DirectoryExists(JoinPath(path, "sparse"));
  const bool blender = FileExists(JoinPath(path, "transforms_train.json"));
  if (colmap) return LoadColmapScene(path, options, scene);
  // `colmap image_undistorter` output inside a workspace: dense/images + dense/sparse/.
  const std::string dense = JoinPath(path, "dense");
  if (!blender && DirectoryExists(JoinPath(dense, "sparse")))
    return LoadColmapScene(dense, options, scene);
  if (blender) return LoadBlenderScene(path, options, scene);
  return Status::Error(path +
                       ": not a scene (expected sparse/ for COLMAP or transforms_train.json "
                       "for Blender)");
}

Status LoadViewImages(const std::string& image_path, const std::string& mask_path,
                      const SceneOptions& options, View* view) {
  Image raw;
  MGSR_RETURN_IF_ERROR(ReadImage(image_path, &raw));
  Camera& cam = view->camera;
  if (raw.width() != cam.width || raw.height() != cam.height) {
    return Status::Error(image_path + ": image is " + std::to_string(raw.width()) + "x" +
                         std::to_string(raw.height()) + " but its camera says " +
                         std::to_string(cam.width) + "x" + std::to_string(cam.height));
  }
  if (raw.channels() == 1) {  // grey: replicate
    Image rgb(raw.width(), raw.height(), 3);
    for (int c = 0; c < 3; ++c)
      std::copy(raw.plane(0), raw.plane(0) + raw.plane_size(), rgb.plane(c));
    raw = std::move(rgb);
  }
  Image rgb = raw.channels() == 4 ? ExtractChannels(raw, 0, 3) : raw;
  Image alpha = raw.channels() == 4 ? ExtractChannels(raw, 3, 1) : Image();
  Image mask;
  if (!mask_path.empty()) {
    Image m;
    MGSR_RETURN_IF_ERROR(ReadImage(mask_path, &m));
    if (m.width() != raw.width() || m.height() != raw.height()) {
      return Status::Error(mask_path + ": mask is " + std::to_string(m.width()) + "x" +
                           std::to_string(m.height()) + " but its image is " +
                           std::to_string(raw.width()) + "x" + std::to_string(raw.height()));
    }
    // A mask may be grey, RGB or RGBA; take the first channel (reference 1.13: mask[0]).
    mask = ExtractChannels(m, 0, 1);
  }
  int width = raw.width(), height = raw.height();
  if (options.downscale > 1) {
    width =
        std::max(1, static_cast<int>(std::lround(static_cast<double>(width) / options.downscale)));
    height =
        std::max(1, static_cast<int>(std::lround(static_cast<double>(height) / options.downscale)));
  }
  if (options.max_width > 0 && width > options.max_width) {
    height = std::max(
        1, static_cast<int>(std::lround(static_cast<double>(height) * options.max_width / width)));
    width = options.max_width;
  }
  if (width != raw.width() || height != raw.height()) {
    rgb = ResizeImage(rgb, width, height);
    if (!alpha.empty()) alpha = ResizeImage(alpha, width, height);
    if (!mask.empty()) mask = ResizeImage(mask, width, height);
    cam = cam.Resized(width, height);
  }
  view->image = std::move(rgb);
  view->alpha = std::move(alpha);
  view->mask = std::move(mask);
  return Status::Ok();
}

void ComputeSceneExtent(Scene* scene) {
  std::vector<int> train = scene->TrainIndices();
  if (train.empty()) train = scene->TestIndices();
  if (train.empty()) return;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  for (int i : train) center += scene->views[i].camera.Center();
  center /= static_cast<double>(train.size());
  double max_dist = 0;
  for (int i : train)
    max_dist = std::max(max_dist, (scene->views[i].camera.Center() - center).norm());
  scene->center = center;
  scene->extent = max_dist > 0 ? 1.1 * max_dist : 1.0;
}

void SampleRandomPoints(int count, uint64_t seed, Scene* scene) {
  std::vector<int> train = scene->TrainIndices();
  if (train.empty() || count <= 0) return;
  // Sample inside the bounding box of the camera centres; accept points that project inside
  // the image and in front of the camera for the required share of views.
  Eigen::Vector3d lo = scene->views[train[0]].camera.Center(), hi = lo;
  for (int i : train) {
    lo = lo.cwiseMin(scene->views[i].camera.Center());
    hi = hi.cwiseMax(scene->views[i].camera.Center());
  }
  const Eigen::Vector3d pad = Eigen::Vector3d::Constant(1e-3 + 0.05 * (hi - lo).norm());
  lo -= pad;
  hi += pad;
  Rng rng(seed ^ 0x5EEDu);
  auto visible_share = [&](const Eigen::Vector3d& X) {
    int seen = 0;
    for (int i : train) {
      const Camera& c = scene->views[i].camera;
      const Eigen::Vector3d Xc = c.WorldToCamera(X);
      if (Xc.z() <= 0.2) continue;
      const Eigen::Vector2d uv = c.CameraToPixel(Xc);
      seen += uv.x() >= 0 && uv.y() >= 0 && uv.x() <= c.width && uv.y() <= c.height;
    }
    return static_cast<double>(seen) / train.size();
  };
  scene->points.clear();
  scene->point_colors.clear();
  for (double required : {1.0, 0.75, 0.5, 0.0}) {
    const int64_t max_tries = static_cast<int64_t>(count) * 200;
    for (int64_t t = 0; t < max_tries && static_cast<int>(scene->points.size()) < count; ++t) {
      const Eigen::Vector3d X(rng.Uniform(lo.x(), hi.x()), rng.Uniform(lo.y(), hi.y()),
                              rng.Uniform(lo.z(), hi.z()));
      if (visible_share(X) >= required) {
        scene->points.push_back(X.cast<float>());
        scene->point_colors.emplace_back(0.5f, 0.5f, 0.5f);
      }
    }
    if (static_cast<int>(scene->points.size()) >= count) break;
  }
  scene->random_points = true;
}

}  // namespace mgsr
