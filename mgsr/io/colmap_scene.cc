// Scene from a COLMAP workspace.
#include <algorithm>
#include <fstream>
#include <map>
#include <set>

#include "mgsr/core/lens.h"
#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/scene.h"

namespace mgsr {
namespace {

// sparse/0 when it holds a model, else sparse/.
std::string FindModelFolder(const std::string& root) {
  const std::string sparse = JoinPath(root, "sparse");
  const std::string zero = JoinPath(sparse, "0");
  for (const char* f : {"cameras.bin", "cameras.txt"}) {
    if (FileExists(JoinPath(zero, f))) return zero;
  }
  return sparse;
}

// masks/<stem>.png, masks/<stem>.jpg, or COLMAP's own convention masks/<name>.png; "" when none.
std::string FindMask(const std::string& root, const std::string& name) {
  const std::string dir = JoinPath(root, "masks");
  const std::string stem = FileStem(name);
  for (const std::string& candidate : {stem + ".png", stem + ".jpg", name + ".png", name}) {
    const std::string p = JoinPath(dir, candidate);
    if (FileExists(p)) return p;
  }
  return "";
}

// Test image names from split.txt or test.txt (one name per line, '#' comments); false if none.
bool ReadTestList(const std::string& root, std::set<std::string>* names, std::string* file) {
  for (const char* f : {"split.txt", "test.txt"}) {
    const std::string p = JoinPath(root, f);
    std::ifstream in(p);
    if (!in) continue;
    std::string line;
    while (std::getline(in, line)) {
      while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
      if (line.empty() || line[0] == '#') continue;
      names->insert(line);
    }
    *file = p;
    return true;
  }
  return false;
}

}  // namespace

Status LoadColmapScene(const std::string& root, const SceneOptions& options, Scene* scene) {
  *scene = Scene();
  scene->root = root;
  scene->source = "colmap";
  const std::string model_dir = FindModelFolder(root);
  ColmapModel model;
  MGSR_RETURN_IF_ERROR(ReadColmapModel(model_dir, &model));
  MGSR_RETURN_IF_ERROR(ValidateColmapModel(model, model_dir));
  if (model.images.empty()) return Status::Error(model_dir + ": the model has no images");

  // Each camera's lens and the pinhole intrinsics it is undistorted to, once per camera (the
  // resampling maps are made per photo as it is read: a camera per photo must not hold a map of
  // every photo at once).
  std::map<uint32_t, Undistortion> lenses;
  std::map<uint32_t, int> views_per_camera;
  for (const ColmapImage& im : model.images) ++views_per_camera[im.camera_id];
  for (const ColmapCamera& c : model.cameras) {
    if (!views_per_camera.count(c.camera_id)) continue;
    const std::string where = model_dir + ": camera " + std::to_string(c.camera_id);
    const CameraModelInfo* info = FindCameraModel(c.model_id);
    if (info == nullptr)
      return Status::Error(where + ": unknown model id " + std::to_string(c.model_id));
    Lens lens;
    Status s = LensFromColmap(info->name, c.params.data(), static_cast<int>(c.params.size()),
                              static_cast<int>(c.width), static_cast<int>(c.height), &lens);
    if (!s.ok()) return s.WithContext(where + ": ");
    Undistortion& u = lenses[c.camera_id];
    MGSR_RETURN_IF_ERROR(MakeUndistortion(lens, false, where, &u));
    if (!lens.IsPinhole()) {
      scene->notes.push_back("camera " + std::to_string(c.camera_id) + " (" +
                             std::to_string(views_per_camera[c.camera_id]) +
                             " views): " + u.Describe());
    }
  }

  // Views sorted by image name (ids need not follow file order).
  std::vector<const ColmapImage*> images;
  for (const ColmapImage& im : model.images) images.push_back(&im);
  std::sort(images.begin(), images.end(),
            [](const ColmapImage* a, const ColmapImage* b) { return a->name < b->name; });

  std::set<std::string> test_names;
  std::string split_file;
  const bool has_split = ReadTestList(root, &test_names, &split_file);
  if (has_split && test_names.empty()) {
    return Status::Error(split_file +
                         ": lists no test views (give one image name per line, or "
                         "remove the file for every 8th image)");
  }
  if (has_split) {
    std::set<std::string> known;
    for (const ColmapImage* im : images) known.insert(im->name);
    for (const std::string& n : test_names) {
      if (!known.count(n))
        return Status::Error(split_file + ": lists '" + n + "', which is not in the model");
    }
  }

  const std::string image_dir = JoinPath(root, "images");
  if (options.load_images && !DirectoryExists(image_dir)) {
    return Status::Error(image_dir + ": images folder is missing");
  }
  const bool has_mask_dir = DirectoryExists(JoinPath(root, "masks"));

  scene->views.resize(images.size());
  for (size_t i = 0; i < images.size(); ++i) {
    const ColmapImage& im = *images[i];
    View& v = scene->views[i];
    v.name = im.name;
    const Undistortion& u = lenses.at(im.camera_id);
    Camera& c = v.camera;
    c.width = u.lens.width;
    c.height = u.lens.height;
    c.fx = u.fx;
    c.fy = u.fy;
    c.cx = u.cx;
    c.cy = u.cy;
    c.SetRotationFromQuaternion(im.qvec[0], im.qvec[1], im.qvec[2], im.qvec[3]);
    c.t = im.tvec;
    if (!c.IsValid()) {
      return Status::Error(model_dir + ": image " + im.name +
                           ": invalid camera (non-positive focal length, zero size or NaN/inf "
                           "values)");
    }
    v.is_test = has_split ? test_names.count(im.name) > 0
                          : (options.test_every > 0 && i % options.test_every == 0);
  }
  if (has_split && test_names.size() >= images.size()) {
    return Status::Error(split_file +
                         ": lists every image as a test view, none is left to train on");
  }

  if (options.load_images) {
    std::vector<Status> statuses(images.size());
#pragma omp parallel for schedule(dynamic)
    for (int i = 0; i < static_cast<int>(images.size()); ++i) {
      View& v = scene->views[i];
      std::string mask_path;
      if (has_mask_dir) {
        mask_path = FindMask(root, v.name);
        if (mask_path.empty()) {
          statuses[i] = Status::Error(JoinPath(root, "masks") + ": no mask for image " + v.name +
                                      " (expected masks/" + FileStem(v.name) + ".png)");
          continue;
        }
      }
      statuses[i] = LoadViewImages(JoinPath(image_dir, v.name), mask_path, options, &v,
                                   &lenses.at(images[i]->camera_id));
    }
    for (const Status& s : statuses) MGSR_RETURN_IF_ERROR(s);
    // Without a masks folder, RGBA images give their alpha as the mask.
    for (View& v : scene->views) {
      if (v.mask.empty() && !v.alpha.empty()) v.mask = v.alpha;
    }
  } else {
    for (View& v : scene->views) {
      if (options.downscale > 1) {
        v.camera = v.camera.Resized(std::max(1, v.camera.width / options.downscale),
                                    std::max(1, v.camera.height / options.downscale));
      }
    }
  }

  if (scene->TrainIndices().empty())
    return Status::Error(root + ": every image is a test image; nothing to train on");
  ComputeSceneExtent(scene);

  for (const ColmapPoint3D& p : model.points) {
    scene->points.push_back(p.xyz.cast<float>());
    scene->point_colors.emplace_back(p.rgb[0] / 255.0f, p.rgb[1] / 255.0f, p.rgb[2] / 255.0f);
  }
  if (scene->points.empty()) {
    SampleRandomPoints(options.random_points, options.seed, scene);
    scene->warnings.push_back(model_dir + ": points3D is empty; initialised " +
                              std::to_string(scene->points.size()) +
                              " random points inside the volume the cameras see");
  }
  return Status::Ok();
}

}  // namespace mgsr
