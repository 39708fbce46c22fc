// Scene from a json camera file: the Blender / NeRF-synthetic pair (transforms_train.json,
// transforms_test.json) or one nerfstudio / instant-ngp transforms.json, with global or per-frame
// intrinsics and lenses (camera_model PINHOLE, OPENCV, OPENCV_FISHEYE; k1..k4, p1, p2).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "mgsr/core/lens.h"
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

double JsonNumber(const json& meta, const char* key, double fallback) {
  return meta.contains(key) && meta[key].is_number() ? meta[key].get<double>() : fallback;
}

// The camera keys a frame or the file may give (a frame's win over the file's).
const char* const kIntrinsicKeys[] = {
    "fl_x",           "fl_y", "cx", "cy", "w",  "h",  "camera_angle_x",
    "camera_angle_y", "k1",   "k2", "k3", "k4", "p1", "p2"};

// Checks the camera keys of `obj` (the file's top level or one frame): numbers where given, sizes
// whole and in range, a camera model this loader knows.
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
  if (obj.contains("camera_model")) {
    const std::string model =
        obj["camera_model"].is_string() ? obj["camera_model"].get<std::string>() : "?";
    if (model != "PINHOLE" && model != "SIMPLE_PINHOLE" && model != "OPENCV" &&
        model != "OPENCV_FISHEYE")
      return Status::Error(where + ": camera_model " + model +
                           " is not supported (PINHOLE, OPENCV and OPENCV_FISHEYE are); undistort "
                           "the photos first");
  }
  return Status::Ok();
}

// The frame's lens from its keys over the file's (nerfstudio: camera_model defaults to OPENCV
// when coefficients are given). Coefficients the model does not have are refused, not dropped.
Status FrameLens(const json& own, const json& meta, int width, int height, double fx, double fy,
                 double cx, double cy, const std::string& where, Lens* lens) {
  const auto number = [&](const char* key) {
    return JsonNumber(own, key, JsonNumber(meta, key, 0.0));
  };
  const auto given = [&](const char* key) { return number(key) != 0.0; };
  const bool any =
      given("k1") || given("k2") || given("k3") || given("k4") || given("p1") || given("p2");
  std::string model = own.contains("camera_model")    ? own["camera_model"].get<std::string>()
                      : meta.contains("camera_model") ? meta["camera_model"].get<std::string>()
                      : any                           ? "OPENCV"
                                                      : "PINHOLE";
  Lens l;
  l.model = model;
  l.width = width;
  l.height = height;
  l.fx = fx;
  l.fy = fy;
  l.cx = cx;
  l.cy = cy;
  const auto refuse = [&](const char* key) {
    return Status::Error(where + ": '" + std::string(key) +
                         "' is not a coefficient of camera_model " + model +
                         (model == "OPENCV" ? " (k4 belongs to OPENCV_FISHEYE)" : "") +
                         (model == "OPENCV_FISHEYE" ? " (p1, p2 belong to OPENCV)" : ""));
  };
  if (model == "PINHOLE" || model == "SIMPLE_PINHOLE") {
    for (const char* key : {"k1", "k2", "k3", "k4", "p1", "p2"})
      if (given(key)) return refuse(key);
  } else if (model == "OPENCV") {
    if (given("k4")) return refuse("k4");
    l.kind = Lens::Kind::kRadial;
    l.k[0] = number("k1");
    l.k[1] = number("k2");
    l.k[2] = number("k3");
    l.p1 = number("p1");
    l.p2 = number("p2");
  } else {  // OPENCV_FISHEYE
    for (const char* key : {"p1", "p2"})
      if (given(key)) return refuse(key);
    l.kind = Lens::Kind::kFisheye;
    for (int i = 0; i < 4; ++i) l.k[i] = number(("k" + std::to_string(i + 1)).c_str());
  }
  *lens = l;
  return Status::Ok();
}

// A key that tells two lenses apart (frames that share one share its undistortion).
std::string LensKey(const Lens& l) {
  char buffer[400];
  std::snprintf(buffer, sizeof(buffer),
                "%s %d %d %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g",
                l.model.c_str(), l.width, l.height, l.fx, l.fy, l.cx, l.cy, l.k[0], l.k[1], l.k[2],
                l.k[3], l.k[4], l.k[5], l.p1, l.p2);
  return buffer;
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
      if (f.contains("camera_model")) fr.own["camera_model"] = f["camera_model"];
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

// nerfstudio's split keys (train_filenames, val_filenames, test_filenames: file_path values) or,
// without them, every test_every-th frame by file_path.
Status SplitFrames(const std::string& path, const json& meta, int test_every,
                   std::vector<Frame>* frames) {
  std::sort(frames->begin(), frames->end(),
            [](const Frame& a, const Frame& b) { return a.name < b.name; });
  const char* test_key = meta.contains("test_filenames")  ? "test_filenames"
                         : meta.contains("val_filenames") ? "val_filenames"
                                                          : nullptr;
  if (test_key == nullptr && !meta.contains("train_filenames")) {
    for (size_t i = 0; i < frames->size(); ++i)
      (*frames)[i].is_test = test_every > 0 && i % test_every == 0;
    return Status::Ok();
  }
  std::set<std::string> known;
  for (const Frame& f : *frames) known.insert(f.name);
  const auto names = [&](const char* key, std::set<std::string>* out) {
    if (key == nullptr || !meta.contains(key)) return Status::Ok();
    if (!meta[key].is_array())
      return Status::Error(path + ": '" + key + "' must be a list of file_path values");
    for (const json& n : meta[key]) {
      if (!n.is_string())
        return Status::Error(path + ": '" + key + "' must be a list of file_path values");
      if (!known.count(n.get<std::string>()))
        return Status::Error(path + ": '" + key + "' lists '" + n.get<std::string>() +
                             "', which no frame's file_path is");
      out->insert(n.get<std::string>());
    }
    return Status::Ok();
  };
  std::set<std::string> train, test;
  MGSR_RETURN_IF_ERROR(names("train_filenames", &train));
  MGSR_RETURN_IF_ERROR(names(test_key, &test));
  // Frames in neither list are left out (as nerfstudio does), unless there is no train list.
  std::vector<Frame> kept;
  for (Frame& f : *frames) {
    f.is_test = test.count(f.name) > 0;
    if (f.is_test || train.empty() || train.count(f.name)) kept.push_back(f);
  }
  *frames = std::move(kept);
  return Status::Ok();
}

// What a frame's camera is before the lens is undone: size, focal lengths, principal point.
struct FrameIntrinsics {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Lens lens;
  std::string lens_key;  // LensKey(lens): frames with one key share an undistortion
};

}  // namespace

Status LoadBlenderScene(const std::string& root, const SceneOptions& options, Scene* scene) {
  *scene = Scene();
  scene->root = root;
  // One nerfstudio / instant-ngp transforms.json, or the Blender train/test pair.
  const bool single = !FileExists(JoinPath(root, "transforms_train.json"));
  scene->source = single ? "nerfstudio" : "blender";
  const std::string main_file = single ? "transforms.json" : "transforms_train.json";
  const std::string main_path = JoinPath(root, main_file);
  std::vector<Frame> frames;
  json train_meta, test_meta;
  MGSR_RETURN_IF_ERROR(ReadTransforms(root, main_file, false, &frames, &train_meta));
  if (frames.empty()) {
    return Status::Error(main_path + ": no " + (single ? "" : "training ") +
                         "frames (its 'frames' array is empty)");
  }
  if (single) {
    MGSR_RETURN_IF_ERROR(SplitFrames(main_path, train_meta, options.test_every, &frames));
  } else if (FileExists(JoinPath(root, "transforms_test.json"))) {
    MGSR_RETURN_IF_ERROR(ReadTransforms(root, "transforms_test.json", true, &frames, &test_meta));
  }
  bool every_frame_has_focal = true;
  for (const Frame& f : frames)
    every_frame_has_focal &= f.own.contains("fl_x") || f.own.contains("camera_angle_x");
  if (!train_meta.contains("camera_angle_x") && !train_meta.contains("fl_x") &&
      !every_frame_has_focal) {
    return Status::Error(main_path + ": needs camera_angle_x or fl_x");
  }

  // Each frame's intrinsics and lens (its own keys over its file's), the size from the json or,
  // where it has none, from the photo.
  std::vector<FrameIntrinsics> intrinsics(frames.size());
  std::vector<Status> statuses(frames.size());
#pragma omp parallel for schedule(dynamic)
  for (int i = 0; i < static_cast<int>(frames.size()); ++i) {
    const Frame& f = frames[i];
    const json& meta = f.is_test && !test_meta.is_null() ? test_meta : train_meta;
    const auto number = [&](const char* key, double fallback) {
      return JsonNumber(f.own, key, JsonNumber(meta, key, fallback));
    };
    FrameIntrinsics& in = intrinsics[i];
    in.width = static_cast<int>(number("w", 0));
    in.height = static_cast<int>(number("h", 0));
    if (in.width <= 0 || in.height <= 0) {
      Image probe;
      statuses[i] = ReadImage(f.image_path, &probe);
      if (!statuses[i].ok()) continue;
      in.width = probe.width();
      in.height = probe.height();
    }
    const double angle = number("camera_angle_x", 0);
    in.fx = number("fl_x", angle > 0 ? 0.5 * in.width / std::tan(0.5 * angle) : 0);
    in.fy = number("fl_y", in.fx);
    in.cx = number("cx", in.width / 2.0);
    in.cy = number("cy", in.height / 2.0);
    const std::string file = f.is_test && !test_meta.is_null() ? "transforms_test.json" : main_file;
    statuses[i] = FrameLens(f.own, meta, in.width, in.height, in.fx, in.fy, in.cx, in.cy,
                            JoinPath(root, file) + ": frame " + f.name, &in.lens);
    in.lens_key = LensKey(in.lens);
  }
  for (const Status& s : statuses) MGSR_RETURN_IF_ERROR(s);
  // Frames that share a lens share its pinhole intrinsics (the resampling maps are made per photo
  // as it is read: per-frame lenses must not hold a map of every photo at once).
  std::map<std::string, Undistortion> lenses;
  std::map<std::string, int> lens_views;
  for (size_t i = 0; i < frames.size(); ++i) {
    const Lens& lens = intrinsics[i].lens;
    const std::string& key = intrinsics[i].lens_key;
    if (lens_views[key]++ > 0) continue;
    MGSR_RETURN_IF_ERROR(
        MakeUndistortion(lens, false, main_path + ": frame " + frames[i].name, &lenses[key]));
  }
  for (const auto& [key, u] : lenses) {
    if (!u.lens.IsPinhole())
      scene->notes.push_back(std::to_string(lens_views[key]) + " views: " + u.Describe());
  }

  scene->views.resize(frames.size());
#pragma omp parallel for schedule(dynamic)
  for (int i = 0; i < static_cast<int>(frames.size()); ++i) {
    const Frame& f = frames[i];
    View& v = scene->views[i];
    v.name = f.name;
    v.is_test = f.is_test;
    const Undistortion& u = lenses.at(intrinsics[i].lens_key);
    Camera& c = v.camera;
    c.width = intrinsics[i].width;
    c.height = intrinsics[i].height;
    c.fx = u.fx;
    c.fy = u.fy;
    c.cx = u.cx;
    c.cy = u.cy;
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
    statuses[i] = LoadViewImages(f.image_path, mask, options, &v, &u);
    if (statuses[i].ok() && v.mask.empty() && !v.alpha.empty()) v.mask = v.alpha;
  }
  for (const Status& s : statuses) MGSR_RETURN_IF_ERROR(s);
  if (!options.load_images && options.downscale > 1) {
    for (View& v : scene->views) {
      v.camera = v.camera.Resized(std::max(1, v.camera.width / options.downscale),
                                  std::max(1, v.camera.height / options.downscale));
    }
  }
  if (scene->TrainIndices().empty())
    return Status::Error(main_path + ": every frame is a test frame; nothing to train on");
  ComputeSceneExtent(scene);

  // Initial points: nerfstudio's ply_file_path (ns-process-data's sparse_pc.ply), else
  // points3d.ply beside the json.
  std::string points_file = JoinPath(root, "points3d.ply");
  if (train_meta.contains("ply_file_path")) {
    if (!train_meta["ply_file_path"].is_string())
      return Status::Error(main_path + ": 'ply_file_path' must be a file name");
    points_file = JoinPath(root, train_meta["ply_file_path"].get<std::string>());
    if (!FileExists(points_file))
      return Status::Error(main_path + ": ply_file_path " + points_file + " does not exist");
  }
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
    scene->warnings.push_back(
        root + ": no initial points (points3d.ply or ply_file_path); initialised " +
        std::to_string(scene->points.size()) + " random points inside the volume the cameras see");
  }
  return Status::Ok();
}

}  // namespace mgsr
