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
