// PLY files: a generic reader (ASCII and binary little-endian) and writer, plus typed helpers for
// triangle meshes / point clouds. Values are held as double columns; element and property order
// and types are preserved so files can be rewritten faithfully.
#pragma once

#include <string>
#include <vector>

#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

struct PlyProperty {
  std::string name;
  std::string type =
      "float";  // char uchar short ushort int uint float double (or int8 ... float64)
  bool is_list = false;
  std::string count_type = "uchar";  // for lists
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;
  // columns[p][i]: scalar property p of item i (unused for list properties).
  std::vector<std::vector<double>> columns;
  // lists[p][i]: list property p of item i (empty for scalar properties).
  std::vector<std::vector<std::vector<int64_t>>> lists;

  int FindProperty(const std::string& name) const;  // -1 when absent
  // Index of scalar property `name` in *index (-1 when absent); an error naming `path` when the
  // property is declared as a list, so a reader never indexes the empty column of a list.
  Status FindScalar(const std::string& path, const std::string& name, int* index) const;
  // Appends a scalar float property filled from `values` (size must equal count).
  void AddColumn(const std::string& name, const std::string& type, std::vector<double> values);
};

enum class PlyFormat { kBinaryLittleEndian, kAscii };

struct PlyData {
  PlyFormat format = PlyFormat::kBinaryLittleEndian;
  std::vector<std::string> comments;
  std::vector<PlyElement> elements;

  PlyElement* FindElement(const std::string& name);
  const PlyElement* FindElement(const std::string& name) const;
};

Status ReadPly(const std::string& path, PlyData* ply);
Status WritePly(const std::string& path, const PlyData& ply);

// Vertices (x, y, z), optional normals (nx, ny, nz), colours (red, green, blue as uchar or float)
// and faces (vertex_indices / vertex_index; polygons are fan-triangulated). A file without faces
// reads as a point cloud (triangles empty).
Status ReadTriangleMesh(const std::string& path, TriangleMesh* mesh);
Status WriteTriangleMesh(const std::string& path, const TriangleMesh& mesh,
                         PlyFormat format = PlyFormat::kBinaryLittleEndian);

}  // namespace mgsr
