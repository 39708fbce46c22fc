// Triangle meshes as binary glTF 2.0 (.glb), the format web viewers, Blender, three.js and Open3D
// open without plug-ins. One mesh, one indexed triangle primitive: POSITION (float32, with the
// bounds the format requires), NORMAL (float32, unit length; computed from the triangles when the
// mesh has none), COLOR_0 (float32 RGB) and 32-bit indices, in one binary chunk.
//
// Colours: glTF vertex colours are *linear*; ours are display (sRGB-encoded) values as in the
// images, so the writer decodes them with the sRGB curve and the reader encodes them back: a
// viewer then shows the colours the PLY shows. A material with metallic 0 and roughness 1 comes
// with them (glTF's default material is fully metallic, which renders vertex colours near black).
//
// Coordinates are the scene's, as in mesh.ply and the splat files, not re-oriented to glTF's +Y
// up: the files of one run overlay each other exactly.
#pragma once

#include <string>

#include "mgsr/core/status.h"
#include "mgsr/core/triangle_mesh.h"

namespace mgsr {

// Written through a temporary file and a rename, never half. An empty mesh is an error (a glTF
// accessor may not have count 0).
Status WriteMeshGlb(const std::string& path, const TriangleMesh& mesh);

// Reads the first primitive of the first mesh of a .glb: triangles (mode 4), float32 positions,
// optional float32 normals, optional colours (float32, or normalised unsigned 8/16-bit; RGB or
// RGBA), indices of 8, 16 or 32 bits or none, interleaved or not. Node transforms are not applied.
// Anything else is an error naming the file and what it found.
Status ReadMeshGlb(const std::string& path, TriangleMesh* mesh);

}  // namespace mgsr
