// COLMAP 3.8 binary model format (colmap/base/reconstruction.cc, Read*/Write*Binary).
#include <limits>

#include "mgsr/io/binary_stream.h"
#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"

namespace mgsr {
namespace {
constexpr uint64_t kInvalidPoint3DId = std::numeric_limits<uint64_t>::max();
}  // namespace

Status ReadCamerasBinary(const std::string& path, std::vector<ColmapCamera>* cameras) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  BinaryReader in(path, data);
  uint64_t num = 0;
  MGSR_RETURN_IF_ERROR(in.Read(&num));
  MGSR_RETURN_IF_ERROR(in.CheckRemaining(num, 4 + 4 + 8 + 8, "cameras"));
  cameras->clear();
  cameras->reserve(num);
  for (uint64_t i = 0; i < num; ++i) {
    ColmapCamera c;
    int32_t model_id = 0;
    MGSR_RETURN_IF_ERROR(in.Read(&c.camera_id));
    MGSR_RETURN_IF_ERROR(in.Read(&model_id));
    MGSR_RETURN_IF_ERROR(in.Read(&c.width));
    MGSR_RETURN_IF_ERROR(in.Read(&c.height));
    const CameraModelInfo* info = FindCameraModel(model_id);
    if (info == nullptr) {
      return Status::Error(path + ": camera " + std::to_string(c.camera_id) +
                           " has unknown camera model id " + std::to_string(model_id) +
                           " (COLMAP 3.8 defines ids 0-10)");
    }
    c.model_id = model_id;
    c.params.resize(info->num_params);
    for (double& p : c.params) MGSR_RETURN_IF_ERROR(in.Read(&p));
    cameras->push_back(std::move(c));
  }
  if (!in.AtEnd()) return Status::Error(path + ": trailing bytes after the last camera (corrupt?)");
  return Status::Ok();
}

Status ReadImagesBinary(const std::string& path, std::vector<ColmapImage>* images) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  BinaryReader in(path, data);
  uint64_t num = 0;
  MGSR_RETURN_IF_ERROR(in.Read(&num));
  MGSR_RETURN_IF_ERROR(in.CheckRemaining(num, 4 + 8 * 7 + 4 + 1 + 8, "images"));
  images->clear();
  images->reserve(num);
  for (uint64_t i = 0; i < num; ++i) {
    ColmapImage im;
    MGSR_RETURN_IF_ERROR(in.Read(&im.image_id));
    for (int k = 0; k < 4; ++k) MGSR_RETURN_IF_ERROR(in.Read(&im.qvec[k]));
    for (int k = 0; k < 3; ++k) MGSR_RETURN_IF_ERROR(in.Read(&im.tvec[k]));
    MGSR_RETURN_IF_ERROR(in.Read(&im.camera_id));
    MGSR_RETURN_IF_ERROR(in.ReadCString(&im.name));
    uint64_t num_points2D = 0;
    MGSR_RETURN_IF_ERROR(in.Read(&num_points2D));
    MGSR_RETURN_IF_ERROR(in.CheckRemaining(num_points2D, 24, "2D points"));
    im.xys.resize(num_points2D);
    im.point3D_ids.resize(num_points2D);
    for (uint64_t k = 0; k < num_points2D; ++k) {
      uint64_t id = 0;
      MGSR_RETURN_IF_ERROR(in.Read(&im.xys[k].x()));
      MGSR_RETURN_IF_ERROR(in.Read(&im.xys[k].y()));
      MGSR_RETURN_IF_ERROR(in.Read(&id));
      im.point3D_ids[k] = id == kInvalidPoint3DId ? -1 : static_cast<int64_t>(id);
    }
    images->push_back(std::move(im));
  }
  if (!in.AtEnd()) return Status::Error(path + ": trailing bytes after the last image (corrupt?)");
  return Status::Ok();
}

Status ReadPoints3DBinary(const std::string& path, std::vector<ColmapPoint3D>* points) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  BinaryReader in(path, data);
  uint64_t num = 0;
  MGSR_RETURN_IF_ERROR(in.Read(&num));
  MGSR_RETURN_IF_ERROR(in.CheckRemaining(num, 8 + 24 + 3 + 8 + 8, "points"));
  points->clear();
  points->reserve(num);
  for (uint64_t i = 0; i < num; ++i) {
    ColmapPoint3D p;
    MGSR_RETURN_IF_ERROR(in.Read(&p.point3D_id));
    for (int k = 0; k < 3; ++k) MGSR_RETURN_IF_ERROR(in.Read(&p.xyz[k]));
    for (int k = 0; k < 3; ++k) MGSR_RETURN_IF_ERROR(in.Read(&p.rgb[k]));
    MGSR_RETURN_IF_ERROR(in.Read(&p.error));
    uint64_t track_length = 0;
    MGSR_RETURN_IF_ERROR(in.Read(&track_length));
    MGSR_RETURN_IF_ERROR(in.CheckRemaining(track_length, 8, "track elements"));
    p.track_image_ids.resize(track_length);
    p.track_point2D_idxs.resize(track_length);
    for (uint64_t k = 0; k < track_length; ++k) {
      MGSR_RETURN_IF_ERROR(in.Read(&p.track_image_ids[k]));
      MGSR_RETURN_IF_ERROR(in.Read(&p.track_point2D_idxs[k]));
    }
    points->push_back(std::move(p));
  }
  if (!in.AtEnd()) return Status::Error(path + ": trailing bytes after the last point (corrupt?)");
  return Status::Ok();
}

Status WriteCamerasBinary(const std::string& path, const std::vector<ColmapCamera>& cameras) {
  BinaryWriter out;
  out.Write<uint64_t>(cameras.size());
  for (const ColmapCamera& c : cameras) {
    out.Write<uint32_t>(c.camera_id);
    out.Write<int32_t>(c.model_id);
    out.Write<uint64_t>(c.width);
    out.Write<uint64_t>(c.height);
    for (double p : c.params) out.Write<double>(p);
  }
  return WriteStringToFileAtomic(path, out.data());
}

Status WriteImagesBinary(const std::string& path, const std::vector<ColmapImage>& images) {
  BinaryWriter out;
  out.Write<uint64_t>(images.size());
  for (const ColmapImage& im : images) {
    out.Write<uint32_t>(im.image_id);
    for (int k = 0; k < 4; ++k) out.Write<double>(im.qvec[k]);
    for (int k = 0; k < 3; ++k) out.Write<double>(im.tvec[k]);
    out.Write<uint32_t>(im.camera_id);
    out.WriteCString(im.name);
    out.Write<uint64_t>(im.xys.size());
    for (size_t k = 0; k < im.xys.size(); ++k) {
      out.Write<double>(im.xys[k].x());
      out.Write<double>(im.xys[k].y());
      const int64_t id = k < im.point3D_ids.size() ? im.point3D_ids[k] : -1;
      out.Write<uint64_t>(id < 0 ? kInvalidPoint3DId : static_cast<uint64_t>(id));
    }
  }
  return WriteStringToFileAtomic(path, out.data());
}

Status WritePoints3DBinary(const std::string& path, const std::vector<ColmapPoint3D>& points) {
  BinaryWriter out;
  out.Write<uint64_t>(points.size());
  for (const ColmapPoint3D& p : points) {
    out.Write<uint64_t>(p.point3D_id);
    for (int k = 0; k < 3; ++k) out.Write<double>(p.xyz[k]);
    for (int k = 0; k < 3; ++k) out.Write<uint8_t>(p.rgb[k]);
    out.Write<double>(p.error);
    out.Write<uint64_t>(p.track_image_ids.size());
    for (size_t k = 0; k < p.track_image_ids.size(); ++k) {
      out.Write<uint32_t>(p.track_image_ids[k]);
      out.Write<uint32_t>(p.track_point2D_idxs[k]);
    }
  }
  return WriteStringToFileAtomic(path, out.data());
}

}  // namespace mgsr
