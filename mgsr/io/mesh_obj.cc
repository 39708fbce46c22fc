#include "mgsr/io/mesh_obj.h"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <vector>

#include "mgsr/io/mesh_glb.h"
#include "mgsr/io/ply.h"

namespace mgsr {
namespace {

bool EndsWith(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  for (size_t i = 0; i < suffix.size(); ++i) {
    const char a = s[s.size() - suffix.size() + i];
    const char b = suffix[i];
    if (std::tolower(static_cast<unsigned char>(a)) != b) return false;
  }
  return true;
}

// Parses a float coordinate that must be finite and representable as float.
bool ParseCoordinate(const std::string& token, double* value) {
  if (token.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(token.c_str(), &end);
  if (end != token.c_str() + token.size() || errno == ERANGE || !std::isfinite(v)) return false;
  if (std::fabs(v) > 3.0e38) return false;  // would overflow float downstream
  *value = v;
  return true;
}

}  // namespace

Status ReadObjMesh(const std::string& path, TriangleMesh* mesh) {
  std::ifstream in(path);
  if (!in) return Status::Error(path + ": cannot open");
  TriangleMesh out;
  std::string line;
  int line_no = 0;
  std::vector<long> face;
  auto where = [&]() { return path + ":" + std::to_string(line_no) + ": "; };
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ss(line);
    std::string tag;
    if (!(ss >> tag) || tag[0] == '#') continue;
    if (tag == "v") {
      Eigen::Vector3d p;
      for (int k = 0; k < 3; ++k) {
        std::string t;
        if (!(ss >> t) || !ParseCoordinate(t, &p[k]))
          return Status::Error(where() + "a vertex needs three finite coordinates");
      }
      out.vertices.push_back(p);
    } else if (tag == "f") {
      face.clear();
      std::string t;
      while (ss >> t) {
        const std::string first = t.substr(0, t.find('/'));
        char* end = nullptr;
        errno = 0;
        const long idx = std::strtol(first.c_str(), &end, 10);
        if (first.empty() || end != first.c_str() + first.size() || errno == ERANGE || idx == 0)
          return Status::Error(where() + "bad face index '" + t + "'");
        const long n = static_cast<long>(out.vertices.size());
        const long zero_based = idx > 0 ? idx - 1 : n + idx;
        if (zero_based < 0 || zero_based >= n)
          return Status::Error(where() + "face index " + first + " out of range (" +
                               std::to_string(n) + " vertices so far)");
        face.push_back(zero_based);
      }
      if (face.size() < 3)
        return Status::Error(where() + "a face needs at least 3 vertices, has " +
                             std::to_string(face.size()));
      for (size_t k = 1; k + 1 < face.size(); ++k)
        out.triangles.emplace_back(static_cast<int>(face[0]), static_cast<int>(face[k]),
                                   static_cast<int>(face[k + 1]));
    }
  }
  if (out.vertices.empty()) return Status::Error(path + ": no vertices");
  if (out.triangles.empty()) return Status::Error(path + ": no faces");
  *mesh = std::move(out);
  return Status::Ok();
}

Status ReadMeshFile(const std::string& path, TriangleMesh* mesh) {
  if (EndsWith(path, ".obj")) return ReadObjMesh(path, mesh);
  if (EndsWith(path, ".glb")) return ReadMeshGlb(path, mesh);
  return ReadTriangleMesh(path, mesh);
}

}  // namespace mgsr
