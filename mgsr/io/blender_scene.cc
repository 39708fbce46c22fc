// Scene from a Blender / NeRF-synthetic folder (transforms_train.json, transforms_test.json).
#include <cmath>
#include <nlohmann/json.hpp>

#include "mgsr/core/triangle_mesh.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/scene.h"

namespace mgsr {
namespace {

using nlohmann::json;

struct Frame {
  std::string image_path, mask_path, name;
  Eigen::Matrix4d c2w_gl;
  bool is_test;
  json own;  // the frame's own intrinsics (nerfstudio: per-frame values win over the file's)
};

// The intrinsic keys a frame or the file may give. Lens distortion is refused rather than ignored:
// these loaders hand the solver pinhole cameras only.
const char* const kIntrinsicKeys[] = {"fl_x",           "fl_y",          "cx", "cy", "w", "h",
                                      "camera_angle_x", "camera_angle_y"};
const char* const kDistortionKeys[] = {"k1", "k2", "k3", "k4", "p1", "p2"};

// Checks the camera keys of `obj` (the file's top level or one frame): numbers where given, sizes
// whole and in range, no lens distortion, a pinhole camera model.
Status CheckCameraKeys(const json& obj, const std::string& where) {
  for (const char* key : kIntrinsicKeys) {
    if (!obj.contains(key)) continue;
    const json& v = obj[key];
    if (!v.is_number() || !std::isfinite(v.get<double>()))
      return Status::Error(where + ": '" + key + "' must be a finite number");
    const std::string k = key;
    if ((k == "w" || k == "h") && (v.get<double>() < 1 || v.get<double>() > 65536 ||
                                   v.get<double>() != std::floor(v.get<double>())))
      return Status::Error(where + ": '" + k + "' must be a whole number of pixels in [1, 65536]");
  }
  for (const char* key : kDistortionKeys) {
    if (obj.contains(key) && !(obj[key].is_number() && obj[key].get<double>() == 0.0))
      return Status::Error(where + ": lens distortion ('" + std::string(key) +
                           "') is not supported here; undistort the photos first (colmap "
                           "image_undistorter, or mgsr_colmap)");
  }
  if (obj.contains("camera_model")) {
    const std::string model =
        obj["camera_model"].is_string() ? obj["camera_model"].get<std::string>() : "?";
    if (model != "PINHOLE" && model != "SIMPLE_PINHOLE")
      return Status::Error(where + ": camera_model " + model +
                           " is not supported here (PINHOLE only); undistort the photos first");
  }
  return Status::Ok();
}

bool HasExtension(const std::string& p) {
  const size_t slash = p.find_last_of('/');
  const size_t dot = p.find_last_of('.');
  return dot != std::string::npos && (slash == std::string::npos || dot > slash) &&
         dot + 1 < p.size() && p.substr(dot) != "./";
}

Status ReadTransforms(const std::string& root, const std::string& file, bool is_test,
                      std::vector<Frame>* frames, json* meta) {
  const std::string path = JoinPath(root, file);
  std::string text;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &text));
  try {
    *meta = json::parse(text);
    if (!meta->is_object() || !meta->contains("frames") || !(*meta)["frames"].is_array()) {
      return Status::Error(path + ": no 'frames' array");
    }
    MGSR_RETURN_IF_ERROR(CheckCameraKeys(*meta, path));
    for (const json& f : (*meta)["frames"]) {
      Frame fr;
      fr.is_test = is_test;
      const std::string fp = f.at("file_path").get<std::string>();
      fr.image_path = JoinPath(root, HasExtension(fp) ? fp : fp + ".png");
      fr.name = fp;
      if (f.contains("mask_path")) fr.mask_path = JoinPath(root, f["mask_path"].get<std::string>());
      const json& m = f.at("transform_matrix");
      if (!m.is_array() || m.size() != 4)
        return Status::Error(path + ": transform_matrix of " + fp + " is not 4x4");
      for (int r = 0; r < 4; ++r) {
        if (!m[r].is_array() || m[r].size() != 4)
          return Status::Error(path + ": transform_matrix of " + fp + " is not 4x4");
        for (int c = 0; c < 4; ++c) {
          // NaN is not valid JSON, but some writers emit it as null or a string.
          if (!m[r][c].is_number())
            return Status::Error(path + ": transform_matrix of " + fp + " has a non-number (NaN?)");
          fr.c2w_gl(r, c) = m[r][c].get<double>();
        }
      }
      if (!fr.c2w_gl.allFinite())
        return Status::Error(path + ": transform_matrix of " + fp + " has NaN/inf");
      MGSR_RETURN_IF_ERROR(CheckCameraKeys(f, path + ": frame " + fp));
      fr.own = json::object();
      for (const char* key : kIntrinsicKeys)
        if (f.contains(key)) fr.own[key] = f[key];
      for (const Frame& other : *frames) {
        if (other.image_path == fr.image_path)
          return Status::Error(path + ": frame " + fp + " is listed twice");
      }
      frames->push_back(fr);
    }
  } catch (const json::exception& e) {
    return Status::Error(path + ": invalid JSON: " + e.what());
  }
  return Status::Ok();
}

double JsonNumber(const json& meta, const char* key, double fallback) {
  return meta.contains(key) && meta[key].is_number() ? meta[key].get<double>() : fallback;
}

}  // namespace

Status LoadBlenderScene(const std::string& root, const SceneOptions& options, Scene* scene) {
  *scene = Scene();
  scene->root = root;
  scene->source = "blender";
  std::vector<Frame> frames;
  json train_meta, test_meta;
  MGSR_RETURN_IF_ERROR(ReadTransforms(root, "transforms_train.json", false, &frames, &train_meta));
  if (frames.empty()) {
    return Status::Error(JoinPath(root, "transforms_train.json") +
                         ": no training frames (its 'frames' array is empty)");
  }
  if (FileExists(JoinPath(root, "transforms_test.json"))) {
    MGSR_RETURN_IF_ERROR(ReadTransforms(root, "transforms_test.json", true, &frames, &test_meta));
  }
  bool every_frame_has_focal = true;
  for (const Frame& f : frames)
    every_frame_has_focal &= f.own.contains("fl_x") || f.own.contains("camera_angle_x");
  if (!train_meta.contains("camera_angle_x") && !train_meta.contains("fl_x") &&
      !every_frame_has_focal) {
    return Status::Error(JoinPath(root, "transforms_train.json") +
                         ": needs camera_angle_x or fl_x");
  }

  scene->views.resize(frames.size());
  std::vector<Status> statuses(frames.size());
#pragma omp parallel for schedule(dynamic)
  for (int i = 0; i < static_cast<int>(frames.size()); ++i) {
    const Frame& f = frames[i];
    const json& meta = f.is_test && !test_meta.is_null() ? test_meta : train_meta;
    View& v = scene->views[i];
    v.name = f.name;
    v.is_test = f.is_test;
    // A frame's own intrinsics win over the file's (nerfstudio's per-frame cameras).
    const auto number = [&](const char* key, double fallback) {
      return JsonNumber(f.own, key, JsonNumber(meta, key, fallback));
    };
    // Size: from the json (nerfstudio-style w/h, checked whole and in range) or the image itself.
    int w = static_cast<int>(number("w", 0)), h = static_cast<int>(number("h", 0));
    Image probe;
    if (w <= 0 || h <= 0) {
      statuses[i] = ReadImage(f.image_path, &probe);
      if (!statuses[i].ok()) continue;
      w = probe.width();
      h = probe.height();
    }
    Camera& c = v.camera;
    c.width = w;
    c.height = h;
    const double angle = number("camera_angle_x", 0);
    c.fx = number("fl_x", angle > 0 ? 0.5 * w / std::tan(0.5 * angle) : 0);
    c.fy = number("fl_y", c.fx);
    c.cx = number("cx", w / 2.0);
    c.cy = number("cy", h / 2.0);
    // OpenGL camera-to-world (y up, looking down -z) -> COLMAP world-to-camera.
    Eigen::Matrix4d c2w = f.c2w_gl;
    c2w.col(1) *= -1;
    c2w.col(2) *= -1;
    const Eigen::Matrix3d Rc2w = c2w.topLeftCorner<3, 3>();
    if (std::abs(Rc2w.determinant() - 1.0) > 1e-4) {
      statuses[i] = Status::Error(f.image_path + ": transform_matrix rotation is not a rotation");
      continue;
    }
    c.R = Rc2w.transpose();
    c.t = -c.R * c2w.topRightCorner<3, 1>();
    if (!c.IsValid()) {
      statuses[i] = Status::Error(f.image_path + ": invalid camera (check camera_angle_x / fl_x)");
      continue;
    }
    std::string mask = f.mask_path;
    if (mask.empty()) {
      const std::string candidate =
          JoinPath(JoinPath(root, "masks"), FileStem(f.image_path) + ".png");
      if (FileExists(candidate)) mask = candidate;
    }
    if (!options.load_images) continue;
    statuses[i] = LoadViewImages(f.image_path, mask, options, &v);
    if (statuses[i].ok() && v.mask.empty() && !v.alpha.empty()) v.mask = v.alpha;
  }
  for (const Status& s : statuses) MGSR_RETURN_IF_ERROR(s);
  if (!options.load_images && options.downscale > 1) {
    for (View& v : scene->views) {
      v.camera = v.camera.Resized(std::max(1, v.camera.width / options.downscale),
                                  std::max(1, v.camera.height / options.downscale));
    }
  }
  ComputeSceneExtent(scene);

  const std::string points_file = JoinPath(root, "points3d.ply");
  if (FileExists(points_file)) {
    TriangleMesh cloud;
    MGSR_RETURN_IF_ERROR(ReadTriangleMesh(points_file, &cloud));
    for (size_t i = 0; i < cloud.vertices.size(); ++i) {
      scene->points.push_back(cloud.vertices[i].cast<float>());
      scene->point_colors.push_back(i < cloud.vertex_colors.size()
                                        ? cloud.vertex_colors[i]
                                        : Eigen::Vector3f(0.5f, 0.5f, 0.5f));
    }
  }
  if (scene->points.empty()) {
    SampleRandomPoints(options.random_points, options.seed, scene);
    scene->warnings.push_back(root + ": no points3d.ply; initialised " +
                              std::to_string(scene->points.size()) +
                              " random points inside the volume the cameras see");
  }
  return Status::Ok();
}

}  // namespace mgsr
