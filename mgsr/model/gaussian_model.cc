#include "mgsr/model/gaussian_model.h"

namespace mgsr {

void GaussianModel::Resize(size_t n) {
  const size_t k = sh_coeffs();
  means.resize(n * 3);
  log_scales.resize(n * 3);
  quats.resize(n * 4);
  opacity_logits.resize(n);
  sh.resize(n * k * 3);
  ref_sh.resize(n * k * 3);
  ref_opacity_logits.resize(n);
  beta_logits.resize(n);
}

}  // namespace mgsr

namespace mgsr {

std::vector<ParamBlock> GaussianModel::Blocks() {
  const int k3 = sh_coeffs() * 3;
  return {{"means", &means, 3},
          {"log_scales", &log_scales, 3},
          {"quats", &quats, 4},
          {"opacity_logits", &opacity_logits, 1},
          {"sh", &sh, k3},
          {"ref_sh", &ref_sh, k3},
          {"ref_opacity_logits", &ref_opacity_logits, 1},
          {"beta_logits", &beta_logits, 1}};
}

}  // namespace mgsr
