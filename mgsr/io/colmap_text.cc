// COLMAP 3.8 text model format (colmap/base/reconstruction.cc, Read*/Write*Text).
#include <cerrno>
#include <cstdlib>
#include <sstream>

#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"

namespace mgsr {
namespace {

std::vector<std::string> SplitWhitespace(const std::string& line) {
  std::vector<std::string> tokens;
  std::istringstream ss(line);
  std::string t;
  while (ss >> t) tokens.push_back(t);
  return tokens;
}

bool ParseDouble(const std::string& s, double* v) {
  char* end = nullptr;
  errno = 0;
  *v = std::strtod(s.c_str(), &end);
  return end != s.c_str() && *end == '\0' && errno != ERANGE;
}

bool ParseInt64(const std::string& s, int64_t* v) {
  char* end = nullptr;
  errno = 0;
  *v = std::strtoll(s.c_str(), &end, 10);
  return end != s.c_str() && *end == '\0' && errno != ERANGE;
}

bool ParseUInt(const std::string& s, uint64_t max_value, uint64_t* v) {
  if (s.empty() || s[0] == '-') return false;
  char* end = nullptr;
  errno = 0;
  *v = std::strtoull(s.c_str(), &end, 10);
  return end != s.c_str() && *end == '\0' && errno != ERANGE && *v <= max_value;
}

// Splits the file into lines, remembering 1-based line numbers for error messages.
struct TextLines {
  std::vector<std::string> lines;
  size_t next = 0;
  // Next line that is neither empty nor a comment; false at the end.
  bool NextDataLine(std::string* line, size_t* line_no) {
    while (next < lines.size()) {
      std::string l = lines[next++];
      if (!l.empty() && l.back() == '\r') l.pop_back();
      const size_t first = l.find_first_not_of(" \t");
      if (first == std::string::npos || l[first] == '#') continue;
      *line = l;
      *line_no = next;
      return true;
    }
    return false;
  }
};

Status LoadLines(const std::string& path, TextLines* text) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  std::istringstream ss(data);
  std::string line;
  while (std::getline(ss, line)) text->lines.push_back(line);
  return Status::Ok();
}

Status LineError(const std::string& path, size_t line_no, const std::string& what) {
  return Status::Error(path + ":" + std::to_string(line_no) + ": " + what);
}

std::string FormatDouble(double v) {
  std::ostringstream ss;
  ss.precision(17);  // lossless for doubles, as COLMAP writes them
  ss << v;
  return ss.str();
}

}  // namespace

Status ReadCamerasText(const std::string& path, std::vector<ColmapCamera>* cameras) {
  TextLines text;
  MGSR_RETURN_IF_ERROR(LoadLines(path, &text));
  cameras->clear();
  std::string line;
  size_t no = 0;
  while (text.NextDataLine(&line, &no)) {
    const std::vector<std::string> tok = SplitWhitespace(line);
    if (tok.size() < 4)
      return LineError(path, no, "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    ColmapCamera c;
    uint64_t id = 0;
    if (!ParseUInt(tok[0], 0xFFFFFFFFull, &id))
      return LineError(path, no, "bad camera id '" + tok[0] + "'");
    c.camera_id = static_cast<uint32_t>(id);
    const CameraModelInfo* info = FindCameraModel(tok[1]);
    if (info == nullptr) return LineError(path, no, "unknown camera model '" + tok[1] + "'");
    c.model_id = info->id;
    if (!ParseUInt(tok[2], ~0ull, &c.width) || !ParseUInt(tok[3], ~0ull, &c.height)) {
      return LineError(path, no, "bad image size");
    }
    if (tok.size() != 4u + info->num_params) {
      return LineError(path, no,
                       std::string(info->name) + " needs " + std::to_string(info->num_params) +
                           " parameters, found " + std::to_string(tok.size() - 4));
    }
    c.params.resize(info->num_params);
    for (int k = 0; k < info->num_params; ++k) {
      if (!ParseDouble(tok[4 + k], &c.params[k]))
        return LineError(path, no, "bad parameter '" + tok[4 + k] + "'");
    }
    cameras->push_back(std::move(c));
  }
  return Status::Ok();
}

Status ReadImagesText(const std::string& path, std::vector<ColmapImage>* images) {
  TextLines text;
  MGSR_RETURN_IF_ERROR(LoadLines(path, &text));
  images->clear();
  std::string line;
  size_t no = 0;
  while (text.NextDataLine(&line, &no)) {
    const std::vector<std::string> tok = SplitWhitespace(line);
    if (tok.size() != 10) {
      return LineError(path, no, "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    }
    ColmapImage im;
    uint64_t id = 0;
    if (!ParseUInt(tok[0], 0xFFFFFFFFull, &id))
      return LineError(path, no, "bad image id '" + tok[0] + "'");
    im.image_id = static_cast<uint32_t>(id);
    for (int k = 0; k < 4; ++k) {
      if (!ParseDouble(tok[1 + k], &im.qvec[k])) return LineError(path, no, "bad quaternion");
    }
    for (int k = 0; k < 3; ++k) {
      if (!ParseDouble(tok[5 + k], &im.tvec[k])) return LineError(path, no, "bad translation");
    }
    if (!ParseUInt(tok[8], 0xFFFFFFFFull, &id))
      return LineError(path, no, "bad camera id '" + tok[8] + "'");
    im.camera_id = static_cast<uint32_t>(id);
    im.name = tok[9];
    // The POINTS2D line follows directly and may be empty.
    std::string points_line;
    if (text.next < text.lines.size()) points_line = text.lines[text.next++];
    const std::vector<std::string> pt = SplitWhitespace(points_line);
    if (pt.size() % 3 != 0) {
      return LineError(path, text.next, "POINTS2D must be triples (X, Y, POINT3D_ID)");
    }
    const size_t n = pt.size() / 3;
    im.xys.resize(n);
    im.point3D_ids.resize(n);
    for (size_t k = 0; k < n; ++k) {
      if (!ParseDouble(pt[3 * k], &im.xys[k].x()) || !ParseDouble(pt[3 * k + 1], &im.xys[k].y()) ||
          !ParseInt64(pt[3 * k + 2], &im.point3D_ids[k])) {
        return LineError(path, text.next, "bad 2D point " + std::to_string(k));
      }
    }
    images->push_back(std::move(im));
  }
  return Status::Ok();
}

Status ReadPoints3DText(const std::string& path, std::vector<ColmapPoint3D>* points) {
  TextLines text;
  MGSR_RETURN_IF_ERROR(LoadLines(path, &text));
  points->clear();
  std::string line;
  size_t no = 0;
  while (text.NextDataLine(&line, &no)) {
    const std::vector<std::string> tok = SplitWhitespace(line);
    if (tok.size() < 8 || (tok.size() - 8) % 2 != 0) {
      return LineError(path, no, "expected POINT3D_ID X Y Z R G B ERROR TRACK[] (pairs)");
    }
    ColmapPoint3D p;
    if (!ParseUInt(tok[0], ~0ull, &p.point3D_id)) return LineError(path, no, "bad point id");
    for (int k = 0; k < 3; ++k) {
      if (!ParseDouble(tok[1 + k], &p.xyz[k])) return LineError(path, no, "bad coordinate");
    }
    for (int k = 0; k < 3; ++k) {
      uint64_t c = 0;
      if (!ParseUInt(tok[4 + k], 255, &c)) return LineError(path, no, "bad colour (0-255)");
      p.rgb[k] = static_cast<uint8_t>(c);
    }
    if (!ParseDouble(tok[7], &p.error)) return LineError(path, no, "bad error");
    const size_t n = (tok.size() - 8) / 2;
    p.track_image_ids.resize(n);
    p.track_point2D_idxs.resize(n);
    for (size_t k = 0; k < n; ++k) {
      uint64_t a = 0, b = 0;
      if (!ParseUInt(tok[8 + 2 * k], 0xFFFFFFFFull, &a) ||
          !ParseUInt(tok[9 + 2 * k], 0xFFFFFFFFull, &b)) {
        return LineError(path, no, "bad track element " + std::to_string(k));
      }
      p.track_image_ids[k] = static_cast<uint32_t>(a);
      p.track_point2D_idxs[k] = static_cast<uint32_t>(b);
    }
    points->push_back(std::move(p));
  }
  return Status::Ok();
}

Status WriteCamerasText(const std::string& path, const std::vector<ColmapCamera>& cameras) {
  std::ostringstream out;
  out << "# Camera list with one line of data per camera:\n"
      << "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
      << "# Number of cameras: " << cameras.size() << "\n";
  for (const ColmapCamera& c : cameras) {
    const CameraModelInfo* info = FindCameraModel(c.model_id);
    if (info == nullptr)
      return Status::Error(path + ": unknown camera model id " + std::to_string(c.model_id));
    out << c.camera_id << " " << info->name << " " << c.width << " " << c.height;
    for (double p : c.params) out << " " << FormatDouble(p);
    out << "\n";
  }
  return WriteStringToFileAtomic(path, out.str());
}

Status WriteImagesText(const std::string& path, const std::vector<ColmapImage>& images) {
  size_t num_obs = 0;
  for (const ColmapImage& im : images) {
    for (int64_t id : im.point3D_ids) num_obs += id >= 0;
  }
  const double mean_obs = images.empty() ? 0.0 : static_cast<double>(num_obs) / images.size();
  std::ostringstream out;
  out << "# Image list with two lines of data per image:\n"
      << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
      << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
      << "# Number of images: " << images.size()
      << ", mean observations per image: " << FormatDouble(mean_obs) << "\n";
  for (const ColmapImage& im : images) {
    out << im.image_id;
    for (int k = 0; k < 4; ++k) out << " " << FormatDouble(im.qvec[k]);
    for (int k = 0; k < 3; ++k) out << " " << FormatDouble(im.tvec[k]);
    out << " " << im.camera_id << " " << im.name << "\n";
    for (size_t k = 0; k < im.xys.size(); ++k) {
      if (k > 0) out << " ";
      const int64_t id = k < im.point3D_ids.size() ? im.point3D_ids[k] : -1;
      out << FormatDouble(im.xys[k].x()) << " " << FormatDouble(im.xys[k].y()) << " " << id;
    }
    out << "\n";
  }
  return WriteStringToFileAtomic(path, out.str());
}

Status WritePoints3DText(const std::string& path, const std::vector<ColmapPoint3D>& points) {
  size_t track_total = 0;
  for (const ColmapPoint3D& p : points) track_total += p.track_image_ids.size();
  const double mean_track = points.empty() ? 0.0 : static_cast<double>(track_total) / points.size();
  std::ostringstream out;
  out << "# 3D point list with one line of data per point:\n"
      << "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
      << "# Number of points: " << points.size()
      << ", mean track length: " << FormatDouble(mean_track) << "\n";
  for (const ColmapPoint3D& p : points) {
    out << p.point3D_id;
    for (int k = 0; k < 3; ++k) out << " " << FormatDouble(p.xyz[k]);
    for (int k = 0; k < 3; ++k) out << " " << static_cast<int>(p.rgb[k]);
    out << " " << FormatDouble(p.error);
    for (size_t k = 0; k < p.track_image_ids.size(); ++k) {
      out << " " << p.track_image_ids[k] << " " << p.track_point2D_idxs[k];
    }
    out << "\n";
  }
  return WriteStringToFileAtomic(path, out.str());
}

}  // namespace mgsr
