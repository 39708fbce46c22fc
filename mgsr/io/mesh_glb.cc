#include "mgsr/io/mesh_glb.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <nlohmann/json.hpp>

#include "mgsr/io/file_util.h"

namespace mgsr {
namespace {

constexpr uint32_t kGlbMagic = 0x46546C67;  // "glTF"
constexpr uint32_t kGlbVersion = 2;
constexpr uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr uint32_t kChunkBin = 0x004E4942;   // "BIN\0"
constexpr int kFloat = 5126, kUnsignedByte = 5121, kUnsignedShort = 5123, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr int kTriangles = 4;

float SrgbToLinear(float c) {
  c = std::clamp(c, 0.0f, 1.0f);
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

float LinearToSrgb(float c) {
  c = std::clamp(c, 0.0f, 1.0f);
  return c <= 0.0031308f ? c * 12.92f : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
}

template <typename T>
void Append(std::string* out, const T& value) {
  out->append(reinterpret_cast<const char*>(&value), sizeof(T));  // the host is little-endian
}

void PadTo4(std::string* s, char fill) {
  while (s->size() % 4 != 0) s->push_back(fill);
}

// One float32 VEC3 accessor over a tightly packed block appended to `bin`.
nlohmann::json AppendVec3Block(const std::vector<float>& xyz, std::string* bin,
                               nlohmann::json* views, bool with_bounds) {
  const size_t offset = bin->size();
  bin->append(reinterpret_cast<const char*>(xyz.data()), xyz.size() * sizeof(float));
  views->push_back({{"buffer", 0},
                    {"byteOffset", offset},
                    {"byteLength", xyz.size() * sizeof(float)},
                    {"target", kArrayBuffer}});
  nlohmann::json accessor = {{"bufferView", views->size() - 1},
                             {"componentType", kFloat},
                             {"count", xyz.size() / 3},
                             {"type", "VEC3"}};
  if (with_bounds) {
    // The format requires POSITION's bounds, and validators compare them with the float32 data.
    float lo[3], hi[3];
    for (int d = 0; d < 3; ++d) lo[d] = hi[d] = xyz[d];
    for (size_t i = 0; i < xyz.size(); i += 3) {
      for (int d = 0; d < 3; ++d) {
        lo[d] = std::min(lo[d], xyz[i + d]);
        hi[d] = std::max(hi[d], xyz[i + d]);
      }
    }
    accessor["min"] = {lo[0], lo[1], lo[2]};
    accessor["max"] = {hi[0], hi[1], hi[2]};
  }
  return accessor;
}

// ---- Reading.

struct GlbFile {
  std::string path;
  nlohmann::json json;
  std::string bin;
};

Status Bad(const std::string& path, const std::string& what) {
  return Status::Error(path + ": not a glTF mesh this reader takes (" + what + ")");
}

Status ParseGlb(const std::string& path, const std::string& data, GlbFile* file) {
  file->path = path;
  uint32_t header[3];
  if (data.size() < sizeof(header)) return Status::Error(path + ": truncated glTF binary header");
  std::memcpy(header, data.data(), sizeof(header));
  if (header[0] != kGlbMagic) return Status::Error(path + ": not a binary glTF file (bad magic)");
  if (header[1] != kGlbVersion)
    return Status::Error(path + ": glTF binary version " + std::to_string(header[1]) +
                         " (only 2 is read)");
  if (header[2] > data.size())
    return Status::Error(path + ": truncated (header says " + std::to_string(header[2]) +
                         " bytes, the file has " + std::to_string(data.size()) + ")");
  size_t pos = sizeof(header);
  bool have_json = false;
  while (pos + 8 <= header[2]) {
    uint32_t length, type;
    std::memcpy(&length, data.data() + pos, 4);
    std::memcpy(&type, data.data() + pos + 4, 4);
    pos += 8;
    if (length > header[2] - pos)
      return Status::Error(path + ": truncated chunk at byte " + std::to_string(pos - 8));
    if (type == kChunkJson && !have_json) {
      file->json = nlohmann::json::parse(data.begin() + pos, data.begin() + pos + length, nullptr,
                                         /*allow_exceptions=*/false);
      if (file->json.is_discarded() || !file->json.is_object())
        return Status::Error(path + ": the glTF JSON chunk does not parse");
      have_json = true;
    } else if (type == kChunkBin && file->bin.empty()) {
      file->bin.assign(data, pos, length);
    }
    pos += length;
  }
  if (!have_json) return Status::Error(path + ": no JSON chunk");
  return Status::Ok();
}

// A JSON member that must be a non-negative integer.
Status GetIndex(const GlbFile& f, const nlohmann::json& obj, const char* key, size_t* value,
                bool required = true, size_t fallback = 0) {
  const auto it = obj.find(key);
  if (it == obj.end()) {
    if (required) return Bad(f.path, std::string("missing \"") + key + "\"");
    *value = fallback;
    return Status::Ok();
  }
  if (!it->is_number_unsigned()) return Bad(f.path, std::string("\"") + key + "\" is not an index");
  *value = it->get<size_t>();
  return Status::Ok();
}

const nlohmann::json* Element(const GlbFile& f, const char* array, size_t index) {
  const auto it = f.json.find(array);
  if (it == f.json.end() || !it->is_array() || index >= it->size()) return nullptr;
  if (!(*it)[index].is_object()) return nullptr;
  return &(*it)[index];
}

// Reads accessor `index` as `count` elements of `components` doubles (normalised integers mapped
// to [0, 1]); `allowed_components` lists the element sizes the caller takes.
Status ReadAccessor(const GlbFile& f, size_t index, std::vector<int> allowed_components,
                    bool allow_integers, std::vector<double>* values, int* components) {
  const nlohmann::json* acc = Element(f, "accessors", index);
  if (!acc) return Bad(f.path, "accessor " + std::to_string(index) + " does not exist");
  if (acc->contains("sparse")) return Bad(f.path, "sparse accessors");
  static const std::pair<const char*, int> kTypes[] = {
      {"SCALAR", 1}, {"VEC2", 2}, {"VEC3", 3}, {"VEC4", 4}};
  const std::string type = acc->value("type", "");
  int n = 0;
  for (const auto& t : kTypes)
    if (type == t.first) n = t.second;
  if (std::find(allowed_components.begin(), allowed_components.end(), n) ==
      allowed_components.end())
    return Bad(f.path, "accessor " + std::to_string(index) + " has type '" + type + "'");
  size_t component_type, count, view_index, acc_offset;
  MGSR_RETURN_IF_ERROR(GetIndex(f, *acc, "componentType", &component_type));
  MGSR_RETURN_IF_ERROR(GetIndex(f, *acc, "count", &count));
  MGSR_RETURN_IF_ERROR(GetIndex(f, *acc, "bufferView", &view_index));
  MGSR_RETURN_IF_ERROR(GetIndex(f, *acc, "byteOffset", &acc_offset, false, 0));
  size_t bytes = 0;
  if (component_type == kFloat || component_type == kUnsignedInt) bytes = 4;
  if (component_type == kUnsignedShort) bytes = 2;
  if (component_type == kUnsignedByte) bytes = 1;
  if (bytes == 0 || (!allow_integers && component_type != kFloat))
    return Bad(f.path, "accessor " + std::to_string(index) + " has component type " +
                           std::to_string(component_type));
  const bool normalized = acc->value("normalized", false);
  const nlohmann::json* view = Element(f, "bufferViews", view_index);
  if (!view) return Bad(f.path, "buffer view " + std::to_string(view_index) + " does not exist");
  size_t buffer, view_offset, view_length, stride;
  MGSR_RETURN_IF_ERROR(GetIndex(f, *view, "buffer", &buffer));
  MGSR_RETURN_IF_ERROR(GetIndex(f, *view, "byteOffset", &view_offset, false, 0));
  MGSR_RETURN_IF_ERROR(GetIndex(f, *view, "byteLength", &view_length));
  const size_t element = bytes * n;
  MGSR_RETURN_IF_ERROR(GetIndex(f, *view, "byteStride", &stride, false, element));
  const nlohmann::json* buf = Element(f, "buffers", buffer);
  if (buffer != 0 || !buf || buf->contains("uri"))
    return Bad(f.path, "data outside the file's binary chunk");
  if (view_offset > f.bin.size() || view_length > f.bin.size() - view_offset)
    return Status::Error(f.path + ": buffer view " + std::to_string(view_index) +
                         " reaches past the binary chunk");
  if (stride < element)
    return Bad(f.path, "byte stride " + std::to_string(stride) + " below the element size");
  if (count > 0 && (acc_offset > view_length || (count - 1) > (view_length - acc_offset) / stride ||
                    (count - 1) * stride + element > view_length - acc_offset))
    return Status::Error(f.path + ": accessor " + std::to_string(index) +
                         " reaches past its buffer view");
  const char* base = f.bin.data() + view_offset + acc_offset;
  values->resize(count * n);
  for (size_t i = 0; i < count; ++i) {
    for (int c = 0; c < n; ++c) {
      const char* p = base + i * stride + c * bytes;
      double v = 0;
      if (component_type == kFloat) {
        float x;
        std::memcpy(&x, p, 4);
        v = x;
      } else if (component_type == kUnsignedInt) {
        uint32_t x;
        std::memcpy(&x, p, 4);
        v = normalized ? x / 4294967295.0 : x;
      } else if (component_type == kUnsignedShort) {
        uint16_t x;
        std::memcpy(&x, p, 2);
        v = normalized ? x / 65535.0 : x;
      } else {
        v = normalized ? static_cast<uint8_t>(*p) / 255.0 : static_cast<uint8_t>(*p);
      }
      (*values)[i * n + c] = v;
    }
  }
  *components = n;
  return Status::Ok();
}

}  // namespace

Status WriteMeshGlb(const std::string& path, const TriangleMesh& mesh) {
  if (mesh.empty()) return Status::Error(path + ": cannot write an empty mesh as glTF");
  const size_t nv = mesh.vertices.size();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      if (t[k] < 0 || static_cast<size_t>(t[k]) >= nv)
        return Status::Error(path + ": a triangle names vertex " + std::to_string(t[k]) + " of " +
                             std::to_string(nv));
    }
  }
  std::vector<Eigen::Vector3d> normals = mesh.vertex_normals;
  if (normals.size() != nv) {
    TriangleMesh copy;
    copy.vertices = mesh.vertices;
    copy.triangles = mesh.triangles;
    copy.ComputeVertexNormals();
    normals = std::move(copy.vertex_normals);
  }

  std::vector<float> positions(nv * 3), unit_normals(nv * 3), colors;
  for (size_t i = 0; i < nv; ++i) {
    Eigen::Vector3d n = normals[i];
    // glTF requires unit normals; a vertex no triangle with area touches has none, and gets +z.
    n = n.norm() > 1e-12 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::UnitZ();
    for (int d = 0; d < 3; ++d) {
      positions[i * 3 + d] = static_cast<float>(mesh.vertices[i][d]);
      unit_normals[i * 3 + d] = static_cast<float>(n[d]);
    }
  }
  if (mesh.vertex_colors.size() == nv) {
    colors.resize(nv * 3);
    for (size_t i = 0; i < nv; ++i)
      for (int d = 0; d < 3; ++d) colors[i * 3 + d] = SrgbToLinear(mesh.vertex_colors[i][d]);
  }

  std::string bin;
  nlohmann::json views = nlohmann::json::array(), accessors = nlohmann::json::array();
  nlohmann::json attributes = nlohmann::json::object();
  accessors.push_back(AppendVec3Block(positions, &bin, &views, true));
  attributes["POSITION"] = accessors.size() - 1;
  accessors.push_back(AppendVec3Block(unit_normals, &bin, &views, false));
  attributes["NORMAL"] = accessors.size() - 1;
  if (!colors.empty()) {
    accessors.push_back(AppendVec3Block(colors, &bin, &views, false));
    attributes["COLOR_0"] = accessors.size() - 1;
  }
  const size_t index_offset = bin.size();
  for (const Eigen::Vector3i& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) Append(&bin, static_cast<uint32_t>(t[k]));
  views.push_back({{"buffer", 0},
                   {"byteOffset", index_offset},
                   {"byteLength", bin.size() - index_offset},
                   {"target", kElementArrayBuffer}});
  accessors.push_back({{"bufferView", views.size() - 1},
                       {"componentType", kUnsignedInt},
                       {"count", mesh.triangles.size() * 3},
                       {"type", "SCALAR"}});

  const nlohmann::json gltf = {{"asset", {{"version", "2.0"}, {"generator", "MGSR-CPU"}}},
                               {"scene", 0},
                               {"scenes", {{{"nodes", {0}}}}},
                               {"nodes", {{{"mesh", 0}, {"name", "mesh"}}}},
                               {"materials",
                                {{{"name", "vertex colour"},
                                  {"pbrMetallicRoughness",
                                   {{"baseColorFactor", {1.0, 1.0, 1.0, 1.0}},
                                    {"metallicFactor", 0.0},
                                    {"roughnessFactor", 1.0}}}}}},
                               {"meshes",
                                {{{"primitives",
                                   {{{"attributes", attributes},
                                     {"indices", accessors.size() - 1},
                                     {"material", 0},
                                     {"mode", kTriangles}}}}}}},
                               {"accessors", accessors},
                               {"bufferViews", views},
                               {"buffers", {{{"byteLength", bin.size()}}}}};

  std::string json = gltf.dump();
  PadTo4(&json, ' ');
  PadTo4(&bin, '\0');
  std::string out;
  out.reserve(12 + 8 + json.size() + 8 + bin.size());
  const size_t total = 12 + 8 + json.size() + 8 + bin.size();
  if (total > UINT32_MAX) return Status::Error(path + ": the mesh is too large for one .glb");
  Append(&out, kGlbMagic);
  Append(&out, kGlbVersion);
  Append(&out, static_cast<uint32_t>(total));
  Append(&out, static_cast<uint32_t>(json.size()));
  Append(&out, kChunkJson);
  out += json;
  Append(&out, static_cast<uint32_t>(bin.size()));
  Append(&out, kChunkBin);
  out += bin;
  return WriteStringToFileAtomic(path, out);
}

Status ReadMeshGlb(const std::string& path, TriangleMesh* mesh) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  GlbFile f;
  MGSR_RETURN_IF_ERROR(ParseGlb(path, data, &f));
  const nlohmann::json* m = Element(f, "meshes", 0);
  if (!m || !m->contains("primitives") || !(*m)["primitives"].is_array() ||
      (*m)["primitives"].empty() || !(*m)["primitives"][0].is_object())
    return Bad(path, "no mesh primitive");
  const nlohmann::json& prim = (*m)["primitives"][0];
  size_t mode;
  MGSR_RETURN_IF_ERROR(GetIndex(f, prim, "mode", &mode, false, kTriangles));
  if (mode != kTriangles) return Bad(path, "primitive mode " + std::to_string(mode));
  if (!prim.contains("attributes") || !prim["attributes"].is_object())
    return Bad(path, "no attributes");
  const nlohmann::json& attr = prim["attributes"];

  TriangleMesh out;
  std::vector<double> v;
  int n = 0;
  size_t index;
  MGSR_RETURN_IF_ERROR(GetIndex(f, attr, "POSITION", &index));
  MGSR_RETURN_IF_ERROR(ReadAccessor(f, index, {3}, false, &v, &n));
  const size_t nv = v.size() / 3;
  for (size_t i = 0; i < nv; ++i) out.vertices.emplace_back(v[i * 3], v[i * 3 + 1], v[i * 3 + 2]);
  if (attr.contains("NORMAL")) {
    MGSR_RETURN_IF_ERROR(GetIndex(f, attr, "NORMAL", &index));
    MGSR_RETURN_IF_ERROR(ReadAccessor(f, index, {3}, false, &v, &n));
    if (v.size() != nv * 3) return Bad(path, "NORMAL and POSITION counts differ");
    for (size_t i = 0; i < nv; ++i)
      out.vertex_normals.emplace_back(v[i * 3], v[i * 3 + 1], v[i * 3 + 2]);
  }
  if (attr.contains("COLOR_0")) {
    MGSR_RETURN_IF_ERROR(GetIndex(f, attr, "COLOR_0", &index));
    MGSR_RETURN_IF_ERROR(ReadAccessor(f, index, {3, 4}, true, &v, &n));
    if (v.size() != nv * n) return Bad(path, "COLOR_0 and POSITION counts differ");
    for (size_t i = 0; i < nv; ++i) {
      Eigen::Vector3f c;
      for (int d = 0; d < 3; ++d) c[d] = LinearToSrgb(static_cast<float>(v[i * n + d]));
      out.vertex_colors.push_back(c);
    }
  }
  std::vector<double> idx;
  if (prim.contains("indices")) {
    MGSR_RETURN_IF_ERROR(GetIndex(f, prim, "indices", &index));
    MGSR_RETURN_IF_ERROR(ReadAccessor(f, index, {1}, true, &idx, &n));
  } else {
    for (size_t i = 0; i < nv; ++i) idx.push_back(static_cast<double>(i));
  }
  if (idx.size() % 3 != 0) return Bad(path, std::to_string(idx.size()) + " indices for triangles");
  for (size_t t = 0; t < idx.size(); t += 3) {
    Eigen::Vector3i tri;
    for (int k = 0; k < 3; ++k) {
      if (idx[t + k] >= static_cast<double>(nv))
        return Status::Error(path + ": index " + std::to_string(static_cast<size_t>(idx[t + k])) +
                             " names a vertex past the " + std::to_string(nv) + " there are");
      tri[k] = static_cast<int>(idx[t + k]);
    }
    out.triangles.push_back(tri);
  }
  *mesh = std::move(out);
  return Status::Ok();
}

}  // namespace mgsr
