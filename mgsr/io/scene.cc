#include "mgsr/io/scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <tuple>

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

namespace {

std::string Number(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.4g", v);
  return buffer;
}

// What no real capture has: a field of view of almost nothing or almost 180 degrees, a principal
// point far outside the image, a camera so far from the others that the scene's extent is
// meaningless, masks that are all background. Each of these trained to an empty result before.
Status ValidateViews(const Scene& scene) {
  const std::string& root = scene.root;
  if (scene.views.empty()) return Status::Error(root + ": the scene has no views");
  constexpr double kMinFovDeg = 0.1, kMaxFovDeg = 179.0, kPi = 3.14159265358979323846;
  for (const View& v : scene.views) {
    const Camera& c = v.camera;
    for (const auto& [focal, side, axis] : {std::make_tuple(c.fx, c.width, "horizontal"),
                                            std::make_tuple(c.fy, c.height, "vertical")}) {
      const double fov = 2 * std::atan(side / (2 * focal)) * 180 / kPi;
      if (!(focal > 0) || !(fov >= kMinFovDeg && fov <= kMaxFovDeg)) {
        return Status::Error(root + ": view " + v.name + ": focal length " + Number(focal) +
                             " px gives a " + axis + " field of view of " + Number(fov) +
                             " degrees (expected " + Number(kMinFovDeg) + " to " +
                             Number(kMaxFovDeg) + ")");
      }
    }
    if (!(c.cx >= -c.width && c.cx <= 2.0 * c.width && c.cy >= -c.height &&
          c.cy <= 2.0 * c.height)) {
      return Status::Error(root + ": view " + v.name + ": principal point (" + Number(c.cx) + ", " +
                           Number(c.cy) + ") lies far outside its " + std::to_string(c.width) +
                           " x " + std::to_string(c.height) + " image");
    }
    if (!c.Center().allFinite()) {
      return Status::Error(root + ": view " + v.name + ": camera centre is not finite");
    }
  }
  // A camera 1000 times farther from the cameras' centre than their median distance; the centre
  // is the per-axis median, which one wild camera cannot drag along.
  Eigen::Vector3d centroid;
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<double> values;
    for (const View& v : scene.views) values.push_back(v.camera.Center()[axis]);
    std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
    centroid[axis] = values[values.size() / 2];
  }
  std::vector<double> distances;
  for (const View& v : scene.views) distances.push_back((v.camera.Center() - centroid).norm());
  std::vector<double> sorted = distances;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];
  for (size_t i = 0; i < scene.views.size(); ++i) {
    if (!std::isfinite(distances[i]) || (median > 0 && distances[i] > 1000 * median)) {
      return Status::Error(root + ": view " + scene.views[i].name + ": camera lies " +
                           Number(distances[i]) +
                           " from the cameras' centre, over 1000 times "
                           "their median distance " +
                           Number(median) + " (a corrupt pose?)");
    }
  }
  if (scene.has_masks()) {
    bool any_foreground = false;
    for (const View& v : scene.views) {
      const float* m = v.mask.data();
      any_foreground =
          any_foreground || std::any_of(m, m + v.mask.size(), [](float x) { return x > 0.0f; });
    }
    if (!any_foreground) {
      return Status::Error(root + ": every mask is empty (all background): nothing to reconstruct");
    }
  }
  return Status::Ok();
}

Status LoadByLayout(const std::string& path, const SceneOptions& options, Scene* scene) {
  const bool colmap = DirectoryExists(JoinPath(path, "sparse"));
  const bool blender = FileExists(JoinPath(path, "transforms_train.json")) ||
                       FileExists(JoinPath(path, "transforms.json"));
  if (colmap) return LoadColmapScene(path, options, scene);
  // `colmap image_undistorter` output inside a workspace: dense/images + dense/sparse/.
  const std::string dense = JoinPath(path, "dense");
  if (!blender && DirectoryExists(JoinPath(dense, "sparse")))
    return LoadColmapScene(dense, options, scene);
  if (blender) return LoadBlenderScene(path, options, scene);
  return Status::Error(path +
                       ": not a scene (expected sparse/ for COLMAP, transforms.json for "
                       "nerfstudio / instant-ngp, or transforms_train.json for Blender)");
}

}  // namespace

Status LoadScene(const std::string& path, const SceneOptions& options, Scene* scene) {
  if (options.downscale < 1) return Status::Error("--downscale must be >= 1");
  if (options.max_width < 0) return Status::Error("--max_width must be >= 0");
  if (options.max_size < 0) return Status::Error("--max_size must be >= 0");
  if (!DirectoryExists(path)) return Status::Error(path + ": scene folder does not exist");
  if (options.far_points < 0) return Status::Error("--far_points must be >= 0");
  if (!(options.far_radius > 1)) return Status::Error("--far_radius must be > 1");
  MGSR_RETURN_IF_ERROR(LoadByLayout(path, options, scene));
  MGSR_RETURN_IF_ERROR(ValidateViews(*scene));
  // Say when the cap made the photos smaller (a user plans time and detail by it).
  const View& first = scene->views.front();
  const int downscaled_long =
      std::max(first.photo_width, first.photo_height) / std::max(1, options.downscale);
  if (options.load_images && options.max_size > 0 && downscaled_long > options.max_size) {
    scene->notes.push_back(
        "resized from " + std::to_string(first.photo_width) + "x" +
        std::to_string(first.photo_height) + " to " + std::to_string(first.camera.width) + "x" +
        std::to_string(first.camera.height) + ": the long side is capped at " +
        std::to_string(options.max_size) + " px (--max_size; 0 keeps the photos' size)");
  }
  AddFarPoints(options.far_points, options.far_radius, options.seed, scene);
  return Status::Ok();
}

Status LoadViewImages(const std::string& image_path, const std::string& mask_path,
                      const SceneOptions& options, View* view, const Undistortion* undistortion) {
  Image raw;
  MGSR_RETURN_IF_ERROR(ReadImage(image_path, &raw));
  Camera& cam = view->camera;
  // A photo whose camera was made from its upright view (its EXIF orientation honoured) while
  // its pixels are stored turned: turn them (COLMAP's own workspaces use the stored grid).
  const int stored_width = raw.width(), stored_height = raw.height();
  int orientation = 1;
  if (raw.width() != cam.width || raw.height() != cam.height) {
    orientation = ExifOrientation(image_path);
    const bool swaps = orientation >= 5;  // a quarter turn: width and height trade places
    const int upright_width = swaps ? raw.height() : raw.width();
    const int upright_height = swaps ? raw.width() : raw.height();
    if (orientation != 1 && upright_width == cam.width && upright_height == cam.height)
      raw = ApplyExifOrientation(raw, orientation);
    else
      orientation = 1;
  }
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
    if (orientation != 1 && m.width() == stored_width && m.height() == stored_height)
      m = ApplyExifOrientation(m, orientation);
    if (m.width() != raw.width() || m.height() != raw.height()) {
      return Status::Error(mask_path + ": mask is " + std::to_string(m.width()) + "x" +
                           std::to_string(m.height()) + " but its image is " +
                           std::to_string(raw.width()) + "x" + std::to_string(raw.height()));
    }
    // A mask may be grey, RGB or RGBA; take the first channel (method.md 1.13: mask[0]).
    mask = ExtractChannels(m, 0, 1);
  }
  if (undistortion != nullptr && !undistortion->lens.IsPinhole()) {
    // The maps for this photo alone, unless the caller made them.
    Undistortion own;
    const Undistortion* u = undistortion;
    if (u->map_x.empty()) {
      MGSR_RETURN_IF_ERROR(MakeUndistortion(u->lens, true, image_path, &own));
      u = &own;
    }
    rgb = UndistortImage(*u, rgb);
    if (!alpha.empty()) alpha = UndistortImage(*u, alpha);
    if (!mask.empty()) mask = UndistortImage(*u, mask);
  }
  int width = raw.width(), height = raw.height();
  if (options.downscale > 1) {
    width =
        std::max(1, static_cast<int>(std::lround(static_cast<double>(width) / options.downscale)));
    height =
        std::max(1, static_cast<int>(std::lround(static_cast<double>(height) / options.downscale)));
  }
  if (options.max_size > 0 && std::max(width, height) > options.max_size) {
    const double scale = static_cast<double>(options.max_size) / std::max(width, height);
    width = std::max(1, static_cast<int>(std::lround(width * scale)));
    height = std::max(1, static_cast<int>(std::lround(height * scale)));
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
  view->photo_width = raw.width();
  view->photo_height = raw.height();
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

void AddFarPoints(int count, double radius_scale, uint64_t seed, Scene* scene) {
  Rng rng(seed ^ 0xFA12u);
  const double radius = radius_scale * scene->extent;
  for (int i = 0; i < count; ++i) {
    // Uniform on the sphere: z uniform in [-1, 1], azimuth uniform (Archimedes).
    const double z = rng.Uniform(-1, 1), phi = rng.Uniform(0, 2 * M_PI);
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const Eigen::Vector3d X =
        scene->center + radius * Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), z);
    scene->points.push_back(X.cast<float>());
    scene->point_colors.emplace_back(0.5f, 0.5f, 0.5f);
  }
}

Status CheckTrainable(const Scene& scene) {
  const std::vector<int> train = scene.TrainIndices();
  if (train.size() < 2)
    return Status::Error(scene.root + ": " + std::to_string(train.size()) +
                         " training view(s); at least 2 are needed (fewer test views: "
                         "--test_every, or the split file)");
  for (int v : train) {
    const Camera& c = scene.views[v].camera;
    if (c.width < 16 || c.height < 16)
      return Status::Error(scene.root + ": view " + scene.views[v].name + " is " +
                           std::to_string(c.width) + "x" + std::to_string(c.height) +
                           " pixels after downscaling; at least 16x16 are needed (a smaller "
                           "--downscale)");
  }
  if (scene.random_points) return Status::Ok();
  size_t seen_twice = 0;
  for (const Eigen::Vector3f& p : scene.points) {
    int seen = 0;
    for (int v : train) {
      const Camera& c = scene.views[v].camera;
      const Eigen::Vector3d x = c.WorldToCamera(p.cast<double>());
      if (!(x.z() > 0)) continue;
      const Eigen::Vector2d q = c.CameraToPixel(x);
      if (q.x() >= 0 && q.y() >= 0 && q.x() <= c.width && q.y() <= c.height && ++seen >= 2) break;
    }
    if (seen >= 2 && ++seen_twice >= 4) return Status::Ok();
  }
  return Status::Error(scene.root + ": only " + std::to_string(seen_twice) + " of the " +
                       std::to_string(scene.points.size()) +
                       " scene points lie in front of two training cameras (at least 4 are "
                       "needed): the cameras look away from the points, or the model has too "
                       "few points");
}

}  // namespace mgsr
