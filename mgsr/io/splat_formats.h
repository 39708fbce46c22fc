// The 3DGS branch in the formats web splat viewers and converters read, besides the PLY
// (model_ply.h):
//   .splat  antimatter15's layout, 32 bytes per splat: position and linear scale as float32, colour
//           and opacity as 4 bytes, the unit quaternion (w, x, y, z) as 4 bytes (q * 128 + 128).
//           Degree-0 colour only; same axes as the PLY; splats sorted by exp(sum of log scales) x
//           opacity, largest first, as viewers that stream the file expect.
//   .spz    Niantic's compressed format, version 3: one gzip stream of a 16-byte header, then each
//           attribute for all splats in turn (24-bit fixed-point positions with 12 fractional bits,
//           opacity bytes, DC colour bytes (0.5 + 0.15 f_dc), log-scale bytes ((s + 10) * 16),
//           quaternions as the "smallest three" in 32 bits, SH bytes (sh * 128 + 128, 5 bits of
//           precision for degree 1, 4 for higher)), written from the published description. The
//           format's axes are right-up-back (OpenGL); ours (COLMAP) are right-down-forward, so y
//           and z flip, with the quaternion and the odd SH coefficients to match.
// Both hold one colour per splat: they carry the transmitted (reflection-free) appearance, as the
// PLY's standard attributes do; the reflected colour, its opacity and beta are dropped (the PLY
// keeps them). Files are written through a temporary name, never half.
#pragma once

#include <string>

#include "mgsr/core/status.h"
#include "mgsr/model/gaussian_model.h"

namespace mgsr {

Status WriteSplatFile(const std::string& path, const GaussianModel& model);
Status WriteSpzFile(const std::string& path, const GaussianModel& model);

// Readers of the same formats (decoding what the writers quantised: a round trip loses only that
// precision). The reflection attributes come back as ReadGaussianPly sets them for a plain 3DGS
// file. The .spz reader takes versions 2 and 3.
Status ReadSplatFile(const std::string& path, GaussianModel* model);
Status ReadSpzFile(const std::string& path, GaussianModel* model);

// "ply,splat,spz,glb" -> the formats, in order, without repeats; an error names an unknown one.
// ply, splat and spz are the 3DGS model's formats; glb adds the mesh as binary glTF (mesh_glb.h)
// beside mesh.ply, which is always written.
Status ParseExportFormats(const std::string& list, std::vector<std::string>* formats);

}  // namespace mgsr
