// Model PLY files. The Gaussian file uses the attribute names of the original 3DGS code
// (x y z nx ny nz f_dc_0..2 f_rest_0.. opacity scale_0..2 rot_0..3), so common splat viewers open
// it, followed by MGSR's reflection attributes (ref_f_dc_*, ref_f_rest_*, ref_opacity, beta).
// The surfel file follows 2DGS (two scales). f_rest is stored channel-major like the originals:
// f_rest_{c * (K - 1) + (k - 1)} is coefficient k of channel c.
#pragma once

#include <string>

#include "mgsr/core/status.h"
#include "mgsr/model/gaussian_model.h"
#include "mgsr/model/surfel_model.h"

namespace mgsr {

Status WriteGaussianPly(const std::string& path, const GaussianModel& model);
// Reads a file written by WriteGaussianPly or by the original 3DGS code (the reflection attributes
// then default to: reflected SH = transmitted DC, reflected opacity 0.1, beta 0.1).
Status ReadGaussianPly(const std::string& path, GaussianModel* model);
// The reflection block of a model read from a plain 3DGS file, as method.md 1.9 initialises it:
// reflected SH = transmitted DC, reflected opacity 0.1, beta 0.1. Needs the model's size and SH
// set.
void SetPlainReflection(GaussianModel* model);

Status WriteSurfelPly(const std::string& path, const SurfelModel& model);
Status ReadSurfelPly(const std::string& path, SurfelModel* model);

}  // namespace mgsr
