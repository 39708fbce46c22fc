// GaussianModel: the 3DGS branch's parameter blocks, structure-of-arrays, raw (pre-activation)
// values as the optimiser sees them. Activations: scale = exp(log_scale), rotation =
// normalise(quat), opacity = sigmoid(logit); reflection parameters of MGSR: reflected SH, reflected
// opacity and the reflected confidence beta (all sigmoid logits), see method.md 2.
#pragma once

#include <cstddef>
#include <vector>

#include "mgsr/model/param_block.h"

namespace mgsr {

// Number of SH coefficients per colour channel for degree d.
constexpr int NumShCoeffs(int degree) { return (degree + 1) * (degree + 1); }

struct GaussianModel {
  int max_sh_degree = 3;
  std::vector<float> means;               // N x 3
  std::vector<float> log_scales;          // N x 3
  std::vector<float> quats;               // N x 4 (w, x, y, z), not necessarily normalised
  std::vector<float> opacity_logits;      // N
  std::vector<float> sh;                  // N x K x 3, K = NumShCoeffs(max_sh_degree); [n][k][rgb]
  std::vector<float> ref_sh;              // N x K x 3 (reflected colour)
  std::vector<float> ref_opacity_logits;  // N
  std::vector<float> beta_logits;         // N (reflected confidence)

  size_t size() const { return opacity_logits.size(); }
  int sh_coeffs() const { return NumShCoeffs(max_sh_degree); }
  void Resize(size_t n);

  // Every parameter block, in a fixed order (the optimiser and the row operations use it).
  std::vector<ParamBlock> Blocks();
  // Density-control row operations (all blocks together).
  void KeepRows(const std::vector<uint8_t>& keep) { mgsr::KeepRows(Blocks(), keep); }
  void AppendCopies(const std::vector<int>& rows) {
    mgsr::AppendRowsFrom(Blocks(), Blocks(), rows);
  }
};

}  // namespace mgsr
