// COLMAP sparse models (cameras, images, points3D) as plain structs, and their binary and text
// readers and writers, byte-compatible with COLMAP 3.8. Records keep the order they were read in,
// so writing what was read reproduces the file.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/status.h"

namespace mgsr {

// COLMAP's camera model table (colmap/base/camera_models.h, 3.8).
struct CameraModelInfo {
  int id;
  const char* name;
  int num_params;
  bool has_distortion;
};
// nullptr when unknown.
const CameraModelInfo* FindCameraModel(int model_id);
const CameraModelInfo* FindCameraModel(const std::string& name);

struct ColmapCamera {
  uint32_t camera_id = 0;
  int model_id = 1;  // PINHOLE
  uint64_t width = 0, height = 0;
  std::vector<double> params;
};

struct ColmapImage {
  uint32_t image_id = 0;
  Eigen::Vector4d qvec{1, 0, 0, 0};  // world-to-camera rotation, (w, x, y, z)
  Eigen::Vector3d tvec = Eigen::Vector3d::Zero();
  uint32_t camera_id = 0;
  std::string name;
  std::vector<Eigen::Vector2d> xys;
  std::vector<int64_t> point3D_ids;  // -1 = no 3D point
};

struct ColmapPoint3D {
  uint64_t point3D_id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  std::array<uint8_t, 3> rgb{0, 0, 0};
  double error = -1;
  std::vector<uint32_t> track_image_ids;
  std::vector<uint32_t> track_point2D_idxs;
};

struct ColmapModel {
  std::vector<ColmapCamera> cameras;
  std::vector<ColmapImage> images;
  std::vector<ColmapPoint3D> points;
};

enum class ColmapFormat { kBinary, kText };

Status ReadCamerasBinary(const std::string& path, std::vector<ColmapCamera>* cameras);
Status ReadImagesBinary(const std::string& path, std::vector<ColmapImage>* images);
Status ReadPoints3DBinary(const std::string& path, std::vector<ColmapPoint3D>* points);
Status ReadCamerasText(const std::string& path, std::vector<ColmapCamera>* cameras);
Status ReadImagesText(const std::string& path, std::vector<ColmapImage>* images);
Status ReadPoints3DText(const std::string& path, std::vector<ColmapPoint3D>* points);

Status WriteCamerasBinary(const std::string& path, const std::vector<ColmapCamera>& cameras);
Status WriteImagesBinary(const std::string& path, const std::vector<ColmapImage>& images);
Status WritePoints3DBinary(const std::string& path, const std::vector<ColmapPoint3D>& points);
Status WriteCamerasText(const std::string& path, const std::vector<ColmapCamera>& cameras);
Status WriteImagesText(const std::string& path, const std::vector<ColmapImage>& images);
Status WritePoints3DText(const std::string& path, const std::vector<ColmapPoint3D>& points);

// Reads `dir`/{cameras,images,points3D}.bin, or the .txt files when the .bin files are absent.
Status ReadColmapModel(const std::string& dir, ColmapModel* model);
Status WriteColmapModel(const std::string& dir, const ColmapModel& model, ColmapFormat format);

// Checks references between the three tables (camera ids, track image ids) and finite numbers.
Status ValidateColmapModel(const ColmapModel& model, const std::string& dir);

// The training camera for an image. Only PINHOLE and SIMPLE_PINHOLE are accepted; any model with
// distortion is refused with a message that says how to undistort.
Status MakePinholeCamera(const ColmapCamera& camera, const ColmapImage& image, Camera* out);

}  // namespace mgsr
