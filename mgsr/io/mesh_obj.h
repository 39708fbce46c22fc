// Wavefront OBJ meshes: vertices ("v x y z") and faces ("f a b c ...", each index possibly
// "a/t/n", negative indices counting back from the last vertex), polygons fan-triangulated. Other
// statements (normals, texture coordinates, groups, materials) are skipped. Bad input (a
// non-finite or overflowing coordinate, an index out of range, a face of fewer than 3 vertices)
// is refused with the file and line named.
#pragma once

#include <string>

#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

Status ReadObjMesh(const std::string& path, TriangleMesh* mesh);

// A mesh file by its extension: .obj, .glb, else PLY.
Status ReadMeshFile(const std::string& path, TriangleMesh* mesh);

}  // namespace mgsr
