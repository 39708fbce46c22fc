#include "mgsr/model/surfel_model.h"

namespace mgsr {

void SurfelModel::Resize(size_t n) {
  means.resize(n * 3);
  log_scales.resize(n * 2);
  quats.resize(n * 4);
  opacity_logits.resize(n);
  sh.resize(n * sh_coeffs() * 3);
}

}  // namespace mgsr

namespace mgsr {

std::vector<ParamBlock> SurfelModel::Blocks() {
  return {{"means", &means, 3},
          {"log_scales", &log_scales, 2},
          {"quats", &quats, 4},
          {"opacity_logits", &opacity_logits, 1},
          {"sh", &sh, sh_coeffs() * 3}};
}

}  // namespace mgsr
