// SurfelModel: the 2DGS branch's parameter blocks (flat disks), structure-of-arrays, raw values.
// scale = exp(log_scale) for the two in-plane axes, rotation = normalise(quat), opacity = sigmoid.
#pragma once

#include <cstddef>
#include <vector>

#include "mgsr/model/gaussian_model.h"

namespace mgsr {

struct SurfelModel {
  int max_sh_degree = 3;
  std::vector<float> means;           // N x 3
  std::vector<float> log_scales;      // N x 2 (tangent axes u, v)
  std::vector<float> quats;           // N x 4 (w, x, y, z)
  std::vector<float> opacity_logits;  // N
  std::vector<float> sh;              // N x K x 3

  size_t size() const { return opacity_logits.size(); }
  int sh_coeffs() const { return NumShCoeffs(max_sh_degree); }
  void Resize(size_t n);

  std::vector<ParamBlock> Blocks();
  void KeepRows(const std::vector<uint8_t>& keep) { mgsr::KeepRows(Blocks(), keep); }
  void AppendCopies(const std::vector<int>& rows) {
    mgsr::AppendRowsFrom(Blocks(), Blocks(), rows);
  }
};

}  // namespace mgsr
