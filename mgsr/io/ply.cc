#include "mgsr/io/ply.h"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <sstream>

#include "mgsr/io/binary_stream.h"
#include "mgsr/io/file_util.h"

namespace mgsr {
namespace {

// A PLY scalar type, parsed once per property (comparing type names for every value made the
// reader and writer spend three quarters of their time in string comparisons).
enum class Scalar { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64, kUnknown };

// Both the classic and the sized names.
Scalar ParseScalar(const std::string& t) {
  if (t == "char" || t == "int8") return Scalar::kInt8;
  if (t == "uchar" || t == "uint8") return Scalar::kUint8;
  if (t == "short" || t == "int16") return Scalar::kInt16;
  if (t == "ushort" || t == "uint16") return Scalar::kUint16;
  if (t == "int" || t == "int32") return Scalar::kInt32;
  if (t == "uint" || t == "uint32") return Scalar::kUint32;
  if (t == "float" || t == "float32") return Scalar::kFloat32;
  if (t == "double" || t == "float64") return Scalar::kFloat64;
  return Scalar::kUnknown;
}

// f(X{}) for the C++ type X of `t`, or unknown() for an unknown type.
template <typename F, typename U>
auto WithScalarType(Scalar t, F&& f, U&& unknown) {
  switch (t) {
    case Scalar::kInt8:
      return f(int8_t{});
    case Scalar::kUint8:
      return f(uint8_t{});
    case Scalar::kInt16:
      return f(int16_t{});
    case Scalar::kUint16:
      return f(uint16_t{});
    case Scalar::kInt32:
      return f(int32_t{});
    case Scalar::kUint32:
      return f(uint32_t{});
    case Scalar::kFloat32:
      return f(float{});
    case Scalar::kFloat64:
      return f(double{});
    case Scalar::kUnknown:
      break;
  }
  return unknown();
}

// Size in bytes, 0 when unknown.
int ScalarSize(Scalar t) {
  return WithScalarType(
      t, [](auto x) { return static_cast<int>(sizeof(x)); }, [] { return 0; });
}

int TypeSize(const std::string& t) { return ScalarSize(ParseScalar(t)); }

Status ReadScalar(BinaryReader* in, Scalar t, double* v) {
  return WithScalarType(
      t,
      [&](auto x) {
        MGSR_RETURN_IF_ERROR(in->Read(&x));
        *v = x;
        return Status::Ok();
      },
      // The header check rules this out.
      [&] { return Status::Error(in->path() + ": unknown PLY type"); });
}

// An unknown type name is written as a double (as before types were parsed).
void WriteScalar(BinaryWriter* out, Scalar t, double v) {
  WithScalarType(
      t, [&](auto x) { out->Write<decltype(x)>(static_cast<decltype(x)>(v)); },
      [&] { out->Write<double>(v); });
}

// The parsed types of an element's properties: values, and list counts (unused for scalars).
struct PropertyTypes {
  std::vector<Scalar> value, count;
  explicit PropertyTypes(const PlyElement& e) {
    for (const PlyProperty& p : e.properties) {
      value.push_back(ParseScalar(p.type));
      count.push_back(ParseScalar(p.count_type));
    }
  }
};

bool IsInteger(Scalar t) { return t != Scalar::kFloat32 && t != Scalar::kFloat64; }
bool IsIntegerType(const std::string& t) { return IsInteger(ParseScalar(t)); }

}  // namespace

int PlyElement::FindProperty(const std::string& n) const {
  for (size_t i = 0; i < properties.size(); ++i) {
    if (properties[i].name == n) return static_cast<int>(i);
  }
  return -1;
}

Status PlyElement::FindScalar(const std::string& path, const std::string& n, int* index) const {
  *index = FindProperty(n);
  if (*index >= 0 && properties[*index].is_list) {
    return Status::Error(path + ": property '" + n + "' of element '" + name +
                         "' is a list, expected a scalar");
  }
  return Status::Ok();
}

void PlyElement::AddColumn(const std::string& n, const std::string& type,
                           std::vector<double> values) {
  PlyProperty p;
  p.name = n;
  p.type = type;
  properties.push_back(p);
  columns.push_back(std::move(values));
  lists.emplace_back();
}

PlyElement* PlyData::FindElement(const std::string& n) {
  for (auto& e : elements) {
    if (e.name == n) return &e;
  }
  return nullptr;
}
const PlyElement* PlyData::FindElement(const std::string& n) const {
  for (const auto& e : elements) {
    if (e.name == n) return &e;
  }
  return nullptr;
}

Status ReadPly(const std::string& path, PlyData* ply) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  *ply = PlyData();
  if (data.compare(0, 3, "ply") != 0)
    return Status::Error(path + ": not a PLY file (no 'ply' magic)");
  const size_t header_end = data.find("end_header");
  if (header_end == std::string::npos)
    return Status::Error(path + ": truncated PLY header (no end_header)");
  size_t body = data.find('\n', header_end);
  if (body == std::string::npos) return Status::Error(path + ": truncated PLY header");
  ++body;

  std::istringstream header(data.substr(0, header_end));
  std::string line;
  bool have_format = false;
  while (std::getline(header, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "format") {
      std::string fmt;
      ls >> fmt;
      if (fmt == "ascii")
        ply->format = PlyFormat::kAscii;
      else if (fmt == "binary_little_endian")
        ply->format = PlyFormat::kBinaryLittleEndian;
      else
        return Status::Error(path + ": unsupported PLY format '" + fmt +
                             "' (ascii and binary_little_endian only)");
      have_format = true;
    } else if (key == "comment" || key == "obj_info") {
      const size_t pos = line.find(' ');
      ply->comments.push_back(pos == std::string::npos ? "" : line.substr(pos + 1));
    } else if (key == "element") {
      PlyElement e;
      long long count = -1;
      ls >> e.name >> count;
      if (e.name.empty() || count < 0)
        return Status::Error(path + ": bad element line '" + line + "'");
      e.count = static_cast<size_t>(count);
      ply->elements.push_back(e);
    } else if (key == "property") {
      if (ply->elements.empty()) return Status::Error(path + ": property before any element");
      PlyProperty p;
      std::string t;
      ls >> t;
      if (t == "list") {
        p.is_list = true;
        ls >> p.count_type >> p.type >> p.name;
        if (TypeSize(p.count_type) == 0)
          return Status::Error(path + ": unknown PLY type " + p.count_type);
      } else {
        p.type = t;
        ls >> p.name;
      }
      if (TypeSize(p.type) == 0) return Status::Error(path + ": unknown PLY type " + p.type);
      ply->elements.back().properties.push_back(p);
    }
  }
  if (!have_format) return Status::Error(path + ": PLY header has no format line");

  // Bound the declared sizes by the file before allocating, so a small corrupt header cannot
  // demand gigabytes: every scalar takes at least one byte of the body (binary: its type's size;
  // ASCII: a digit), every list at least its count.
  const uint64_t body_bytes = data.size() - body;
  uint64_t least_bytes = 0;
  for (const PlyElement& e : ply->elements) {
    uint64_t item_bytes = 0;
    for (const PlyProperty& p : e.properties) {
      const int size = TypeSize(p.is_list ? p.count_type : p.type);
      item_bytes += ply->format == PlyFormat::kAscii ? 1 : static_cast<uint64_t>(size);
    }
    const bool overflow = item_bytes > 0 && e.count > (UINT64_MAX - least_bytes) / item_bytes;
    if (e.count > data.size() || overflow || least_bytes + e.count * item_bytes > body_bytes) {
      return Status::Error(path + ": element '" + e.name + "' declares " + std::to_string(e.count) +
                           " items of " + std::to_string(e.properties.size()) +
                           " properties, more than the file can hold (corrupt or truncated)");
    }
    least_bytes += e.count * item_bytes;
  }
  for (PlyElement& e : ply->elements) {
    e.columns.assign(e.properties.size(), {});
    e.lists.assign(e.properties.size(), {});
    for (size_t p = 0; p < e.properties.size(); ++p) {
      if (e.properties[p].is_list)
        e.lists[p].resize(e.count);
      else
        e.columns[p].resize(e.count);
    }
  }

  if (ply->format == PlyFormat::kBinaryLittleEndian) {
    const std::string body_data = data.substr(body);
    BinaryReader in(path, body_data);
    for (PlyElement& e : ply->elements) {
      const PropertyTypes types(e);
      for (size_t i = 0; i < e.count; ++i) {
        for (size_t p = 0; p < e.properties.size(); ++p) {
          const PlyProperty& prop = e.properties[p];
          if (!prop.is_list) {
            MGSR_RETURN_IF_ERROR(ReadScalar(&in, types.value[p], &e.columns[p][i]));
            continue;
          }
          double n = 0;
          MGSR_RETURN_IF_ERROR(ReadScalar(&in, types.count[p], &n));
          if (n < 0) return Status::Error(path + ": negative list length");
          MGSR_RETURN_IF_ERROR(in.CheckRemaining(static_cast<uint64_t>(n),
                                                 ScalarSize(types.value[p]), "list items"));
          auto& list = e.lists[p][i];
          list.resize(static_cast<size_t>(n));
          for (auto& v : list) {
            double x = 0;
            MGSR_RETURN_IF_ERROR(ReadScalar(&in, types.value[p], &x));
            v = static_cast<int64_t>(x);
          }
        }
      }
    }
  } else {
    std::istringstream in(data.substr(body));
    for (PlyElement& e : ply->elements) {
      for (size_t i = 0; i < e.count; ++i) {
        for (size_t p = 0; p < e.properties.size(); ++p) {
          const PlyProperty& prop = e.properties[p];
          if (!prop.is_list) {
            if (!(in >> e.columns[p][i])) {
              return Status::Error(path + ": truncated or malformed ASCII data in element '" +
                                   e.name + "' item " + std::to_string(i));
            }
            // As the binary reader: a value its declared type cannot hold is refused, not
            // rounded to infinity later (a float32 file read back would hold inf there).
            const double x = e.columns[p][i];
            const bool single = prop.type == "float" || prop.type == "float32";
            if (!std::isfinite(x) || (single && std::fabs(x) > 3.4028234663852886e38)) {
              return Status::Error(path + ": element '" + e.name + "' item " + std::to_string(i) +
                                   " property '" + prop.name + "' is out of range for " +
                                   prop.type);
            }
            continue;
          }
          long long n = 0;
          if (!(in >> n) || n < 0 || n > 1 << 20) {
            return Status::Error(path + ": truncated or malformed list in element '" + e.name +
                                 "'");
          }
          auto& list = e.lists[p][i];
          list.resize(static_cast<size_t>(n));
          for (auto& v : list) {
            if (!(in >> v))
              return Status::Error(path + ": truncated list in element '" + e.name + "'");
          }
        }
      }
    }
  }
  return Status::Ok();
}

Status WritePly(const std::string& path, const PlyData& ply) {
  std::ostringstream header;
  header << "ply\nformat " << (ply.format == PlyFormat::kAscii ? "ascii" : "binary_little_endian")
         << " 1.0\n";
  for (const auto& c : ply.comments) header << "comment " << c << "\n";
  for (const PlyElement& e : ply.elements) {
    header << "element " << e.name << " " << e.count << "\n";
    for (size_t p = 0; p < e.properties.size(); ++p) {
      const PlyProperty& prop = e.properties[p];
      if (prop.is_list) {
        header << "property list " << prop.count_type << " " << prop.type << " " << prop.name
               << "\n";
      } else {
        header << "property " << prop.type << " " << prop.name << "\n";
      }
      const size_t have = prop.is_list ? e.lists[p].size() : e.columns[p].size();
      if (have != e.count) {
        return Status::Error(path + ": internal error: property '" + prop.name + "' has " +
                             std::to_string(have) + " values for " + std::to_string(e.count) +
                             " items");
      }
    }
  }
  header << "end_header\n";

  std::string out = header.str();
  if (ply.format == PlyFormat::kBinaryLittleEndian) {
    BinaryWriter w;
    for (const PlyElement& e : ply.elements) {
      const PropertyTypes types(e);
      for (size_t i = 0; i < e.count; ++i) {
        for (size_t p = 0; p < e.properties.size(); ++p) {
          const PlyProperty& prop = e.properties[p];
          if (!prop.is_list) {
            WriteScalar(&w, types.value[p], e.columns[p][i]);
            continue;
          }
          WriteScalar(&w, types.count[p], static_cast<double>(e.lists[p][i].size()));
          for (int64_t v : e.lists[p][i]) WriteScalar(&w, types.value[p], static_cast<double>(v));
        }
      }
    }
    out += w.data();
  } else {
    std::ostringstream body;
    body.precision(9);
    for (const PlyElement& e : ply.elements) {
      const PropertyTypes types(e);
      for (size_t i = 0; i < e.count; ++i) {
        for (size_t p = 0; p < e.properties.size(); ++p) {
          const PlyProperty& prop = e.properties[p];
          if (p > 0) body << " ";
          if (!prop.is_list) {
            if (IsInteger(types.value[p]))
              body << static_cast<long long>(e.columns[p][i]);
            else
              body << e.columns[p][i];
            continue;
          }
          body << e.lists[p][i].size();
          for (int64_t v : e.lists[p][i]) body << " " << v;
        }
        body << "\n";
      }
    }
    out += body.str();
  }
  return WriteStringToFileAtomic(path, out);
}

Status ReadTriangleMesh(const std::string& path, TriangleMesh* mesh) {
  PlyData ply;
  MGSR_RETURN_IF_ERROR(ReadPly(path, &ply));
  *mesh = TriangleMesh();
  const PlyElement* v = ply.FindElement("vertex");
  if (v == nullptr) return Status::Error(path + ": PLY has no 'vertex' element");
  int ix, iy, iz, inx, iny, inz, ir, ig, ib;
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "x", &ix));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "y", &iy));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "z", &iz));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "nx", &inx));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "ny", &iny));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "nz", &inz));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "red", &ir));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "green", &ig));
  MGSR_RETURN_IF_ERROR(v->FindScalar(path, "blue", &ib));
  if (ix < 0 || iy < 0 || iz < 0) return Status::Error(path + ": vertices lack x, y, z");
  mesh->vertices.resize(v->count);
  for (size_t i = 0; i < v->count; ++i) {
    mesh->vertices[i] = {v->columns[ix][i], v->columns[iy][i], v->columns[iz][i]};
    if (!mesh->vertices[i].allFinite()) {
      return Status::Error(path + ": vertex " + std::to_string(i) + " has NaN/inf coordinates");
    }
  }
  if (inx >= 0 && iny >= 0 && inz >= 0) {
    mesh->vertex_normals.resize(v->count);
    for (size_t i = 0; i < v->count; ++i) {
      mesh->vertex_normals[i] = {v->columns[inx][i], v->columns[iny][i], v->columns[inz][i]};
    }
  }
  if (ir >= 0 && ig >= 0 && ib >= 0) {
    const double scale = IsIntegerType(v->properties[ir].type) ? 1.0 / 255.0 : 1.0;
    mesh->vertex_colors.resize(v->count);
    for (size_t i = 0; i < v->count; ++i) {
      mesh->vertex_colors[i] =
          Eigen::Vector3d(v->columns[ir][i], v->columns[ig][i], v->columns[ib][i]).cast<float>() *
          static_cast<float>(scale);
    }
  }
  const PlyElement* f = ply.FindElement("face");
  if (f != nullptr) {
    int il = f->FindProperty("vertex_indices");
    if (il < 0) il = f->FindProperty("vertex_index");
    if (il < 0 || !f->properties[il].is_list)
      return Status::Error(path + ": faces lack vertex_indices");
    if (!IsIntegerType(f->properties[il].type))
      return Status::Error(path + ": face indices are declared " + f->properties[il].type +
                           "; they must be an integer type");
    for (size_t i = 0; i < f->count; ++i) {
      const auto& idx = f->lists[il][i];
      if (idx.size() < 3)
        return Status::Error(path + ": face " + std::to_string(i) + " has " +
                             std::to_string(idx.size()) + " vertices (at least 3)");
      for (int64_t k : idx) {
        if (k < 0 || k >= static_cast<int64_t>(v->count)) {
          return Status::Error(path + ": face " + std::to_string(i) + " refers to vertex " +
                               std::to_string(k) + " of " + std::to_string(v->count));
        }
      }
      for (size_t k = 2; k < idx.size(); ++k) {
        mesh->triangles.emplace_back(static_cast<int>(idx[0]), static_cast<int>(idx[k - 1]),
                                     static_cast<int>(idx[k]));
      }
    }
  }
  return Status::Ok();
}

Status WriteTriangleMesh(const std::string& path, const TriangleMesh& mesh, PlyFormat format) {
  PlyData ply;
  ply.format = format;
  ply.comments.push_back("written by MGSR-CPU");
  PlyElement v;
  v.name = "vertex";
  v.count = mesh.vertices.size();
  std::vector<double> col(v.count);
  for (int d = 0; d < 3; ++d) {
    for (size_t i = 0; i < v.count; ++i) col[i] = mesh.vertices[i][d];
    v.AddColumn(std::string(1, "xyz"[d]), "float", col);
  }
  if (mesh.vertex_normals.size() == v.count && v.count > 0) {
    const char* names[3] = {"nx", "ny", "nz"};
    for (int d = 0; d < 3; ++d) {
      for (size_t i = 0; i < v.count; ++i) col[i] = mesh.vertex_normals[i][d];
      v.AddColumn(names[d], "float", col);
    }
  }
  if (mesh.vertex_colors.size() == v.count && v.count > 0) {
    const char* names[3] = {"red", "green", "blue"};
    for (int d = 0; d < 3; ++d) {
      for (size_t i = 0; i < v.count; ++i) {
        col[i] = std::lround(std::min(1.0f, std::max(0.0f, mesh.vertex_colors[i][d])) * 255.0f);
      }
      v.AddColumn(names[d], "uchar", col);
    }
  }
  ply.elements.push_back(std::move(v));
  PlyElement f;
  f.name = "face";
  f.count = mesh.triangles.size();
  PlyProperty p;
  p.name = "vertex_indices";
  p.type = "int";
  p.is_list = true;
  f.properties.push_back(p);
  f.columns.emplace_back();
  f.lists.emplace_back(f.count);
  for (size_t i = 0; i < f.count; ++i) {
    f.lists[0][i] = {mesh.triangles[i][0], mesh.triangles[i][1], mesh.triangles[i][2]};
  }
  ply.elements.push_back(std::move(f));
  return WritePly(path, ply);
}

}  // namespace mgsr
