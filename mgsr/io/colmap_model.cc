#include "mgsr/io/colmap_model.h"

#include <cmath>
#include <unordered_set>

#include "mgsr/io/file_util.h"

namespace mgsr {
namespace {

// colmap/base/camera_models.h (3.8): ids are stable and written into the binary format.
constexpr CameraModelInfo kCameraModels[] = {
    {0, "SIMPLE_PINHOLE", 3, false},
    {1, "PINHOLE", 4, false},
    {2, "SIMPLE_RADIAL", 4, true},
    {3, "RADIAL", 5, true},
    {4, "OPENCV", 8, true},
    {5, "OPENCV_FISHEYE", 8, true},
    {6, "FULL_OPENCV", 12, true},
    {7, "FOV", 5, true},
    {8, "SIMPLE_RADIAL_FISHEYE", 4, true},
    {9, "RADIAL_FISHEYE", 5, true},
    {10, "THIN_PRISM_FISHEYE", 12, true},
};

bool AllFinite(const std::vector<double>& v) {
  for (double x : v) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

}  // namespace

const CameraModelInfo* FindCameraModel(int model_id) {
  for (const auto& m : kCameraModels) {
    if (m.id == model_id) return &m;
  }
  return nullptr;
}

const CameraModelInfo* FindCameraModel(const std::string& name) {
  for (const auto& m : kCameraModels) {
    if (name == m.name) return &m;
  }
  return nullptr;
}

Status ReadColmapModel(const std::string& dir, ColmapModel* model) {
  if (!DirectoryExists(dir)) return Status::Error(dir + ": COLMAP model folder does not exist");
  const bool binary =
      FileExists(JoinPath(dir, "cameras.bin")) || FileExists(JoinPath(dir, "images.bin"));
  if (binary) {
    MGSR_RETURN_IF_ERROR(ReadCamerasBinary(JoinPath(dir, "cameras.bin"), &model->cameras));
    MGSR_RETURN_IF_ERROR(ReadImagesBinary(JoinPath(dir, "images.bin"), &model->images));
    MGSR_RETURN_IF_ERROR(ReadPoints3DBinary(JoinPath(dir, "points3D.bin"), &model->points));
  } else {
    if (!FileExists(JoinPath(dir, "cameras.txt"))) {
      return Status::Error(dir + ": no COLMAP model here (neither cameras.bin nor cameras.txt)");
    }
    MGSR_RETURN_IF_ERROR(ReadCamerasText(JoinPath(dir, "cameras.txt"), &model->cameras));
    MGSR_RETURN_IF_ERROR(ReadImagesText(JoinPath(dir, "images.txt"), &model->images));
    MGSR_RETURN_IF_ERROR(ReadPoints3DText(JoinPath(dir, "points3D.txt"), &model->points));
  }
  return Status::Ok();
}

Status WriteColmapModel(const std::string& dir, const ColmapModel& model, ColmapFormat format) {
  MGSR_RETURN_IF_ERROR(MakeDirectories(dir));
  if (format == ColmapFormat::kBinary) {
    MGSR_RETURN_IF_ERROR(WriteCamerasBinary(JoinPath(dir, "cameras.bin"), model.cameras));
    MGSR_RETURN_IF_ERROR(WriteImagesBinary(JoinPath(dir, "images.bin"), model.images));
    return WritePoints3DBinary(JoinPath(dir, "points3D.bin"), model.points);
  }
  MGSR_RETURN_IF_ERROR(WriteCamerasText(JoinPath(dir, "cameras.txt"), model.cameras));
  MGSR_RETURN_IF_ERROR(WriteImagesText(JoinPath(dir, "images.txt"), model.images));
  return WritePoints3DText(JoinPath(dir, "points3D.txt"), model.points);
}

Status ValidateColmapModel(const ColmapModel& model, const std::string& dir) {
  std::unordered_set<uint32_t> camera_ids, image_ids;
  std::unordered_set<std::string> image_names;
  // Far beyond any sensor, and within int: a larger value is a corrupt field (2^32 + 48 must not
  // read as 48).
  constexpr uint64_t kMaxSide = 1u << 16;
  for (const ColmapCamera& c : model.cameras) {
    if (!camera_ids.insert(c.camera_id).second) {
      return Status::Error(dir + ": camera id " + std::to_string(c.camera_id) + " appears twice");
    }
    if (c.width == 0 || c.height == 0 || c.width > kMaxSide || c.height > kMaxSide) {
      return Status::Error(dir + ": camera " + std::to_string(c.camera_id) + " has size " +
                           std::to_string(c.width) + " x " + std::to_string(c.height) +
                           " (expected 1 to " + std::to_string(kMaxSide) + " pixels a side)");
    }
    if (!AllFinite(c.params)) {
      return Status::Error(dir + ": camera " + std::to_string(c.camera_id) +
                           " has NaN/inf parameters");
    }
  }
  for (const ColmapImage& im : model.images) {
    if (!image_ids.insert(im.image_id).second) {
      return Status::Error(dir + ": image id " + std::to_string(im.image_id) + " appears twice");
    }
    if (!camera_ids.count(im.camera_id)) {
      return Status::Error(dir + ": image " + im.name + " refers to missing camera " +
                           std::to_string(im.camera_id));
    }
    if (!im.qvec.allFinite() || !im.tvec.allFinite()) {
      return Status::Error(dir + ": image " + im.name + " has a NaN/inf pose");
    }
    if (!image_names.insert(im.name).second) {
      return Status::Error(dir + ": image name " + im.name +
                           " appears twice (two poses for one photo)");
    }
    // COLMAP normalises quaternions on reading, so any finite non-zero norm is a pose; a zero
    // norm, or one that overflows (which would normalise to nothing and read as the identity), is
    // a corrupt record.
    const double norm = im.qvec.norm();
    if (!std::isfinite(norm) || norm < 1e-12) {
      return Status::Error(dir + ": image " + im.name + " has a quaternion of norm " +
                           std::to_string(norm) + " (zero or overflowing: not a rotation)");
    }
  }
  for (const ColmapPoint3D& p : model.points) {
    if (!p.xyz.allFinite()) {
      return Status::Error(dir + ": point " + std::to_string(p.point3D_id) +
                           " has NaN/inf coordinates");
    }
  }
  return Status::Ok();
}

Status MakePinholeCamera(const ColmapCamera& camera, const ColmapImage& image, Camera* out) {
  const CameraModelInfo* info = FindCameraModel(camera.model_id);
  if (info == nullptr) {
    return Status::Error("camera " + std::to_string(camera.camera_id) + ": unknown model id " +
                         std::to_string(camera.model_id));
  }
  if (info->has_distortion) {
    return Status::Error("camera " + std::to_string(camera.camera_id) + " uses the " + info->name +
                         " model with lens distortion; MGSR trains on PINHOLE or SIMPLE_PINHOLE "
                         "cameras only: run `colmap image_undistorter` and point at its output");
  }
  Camera c;
  c.width = static_cast<int>(camera.width);
  c.height = static_cast<int>(camera.height);
  if (info->id == 0) {  // SIMPLE_PINHOLE: f, cx, cy
    c.fx = c.fy = camera.params[0];
    c.cx = camera.params[1];
    c.cy = camera.params[2];
  } else {  // PINHOLE: fx, fy, cx, cy
    c.fx = camera.params[0];
    c.fy = camera.params[1];
    c.cx = camera.params[2];
    c.cy = camera.params[3];
  }
  c.SetRotationFromQuaternion(image.qvec[0], image.qvec[1], image.qvec[2], image.qvec[3]);
  c.t = image.tvec;
  if (!c.IsValid()) {
    return Status::Error("image " + image.name +
                         ": invalid camera (non-positive focal length, "
                         "zero size or NaN/inf values)");
  }
  *out = c;
  return Status::Ok();
}

}  // namespace mgsr
