#include "solvers/adam.h"

#include <glog/logging.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace mgsr {

std::string Adam::Step(const std::vector<ParamBlock>& params, const std::vector<ParamBlock>& grads,
                       const LearningRates& learning_rates) {
  std::vector<float> rates;
  std::string nonfinite;
  CHECK_EQ(params.size(), grads.size());
  for (size_t b = 0; b < params.size(); ++b) {
    const ParamBlock& p = params[b];
    const ParamBlock& g = grads[b];
    CHECK_EQ(p.name, g.name);
    CHECK_EQ(p.data->size(), g.data->size()) << p.name;
    BlockState& s = state_[p.name];
    s.width = p.width;
    if (s.m.size() != p.data->size()) {
      s.m.resize(p.data->size(), 0.0f);
      s.v.resize(p.data->size(), 0.0f);
    }
    rates.assign(p.width, 0.0f);
    learning_rates(p.name, p.width, &rates);
    if (std::all_of(rates.begin(), rates.end(), [](float r) { return r == 0.0f; })) continue;
    ++s.step;
    const float b1 = static_cast<float>(beta1), b2 = static_cast<float>(beta2);
    const float c1 = static_cast<float>(1.0 / (1.0 - std::pow(beta1, static_cast<double>(s.step))));
    const float c2 = static_cast<float>(1.0 / (1.0 - std::pow(beta2, static_cast<double>(s.step))));
    const float e = static_cast<float>(eps);
    const int width = p.width;
    const float* lr = rates.data();
    float* x = p.data->data();
    const float* gr = g.data->data();
    float* m = s.m.data();
    float* v = s.v.data();
    const int64_t n = static_cast<int64_t>(p.data->size());
    // By rows and columns (the column's rate without a division per entry); NaN and infinities in
    // the gradient, the floats whose exponent bits are all set, are caught in the same pass.
    uint32_t nonfinite_bits = 0;
    const int64_t rows = n / width;
#pragma omp parallel for schedule(static) reduction(| : nonfinite_bits) if (n > 100000)
    for (int64_t r = 0; r < rows; ++r) {
      for (int c = 0; c < width; ++c) {
        const int64_t i = r * width + c;
        uint32_t bits;
        std::memcpy(&bits, &gr[i], sizeof(bits));
        nonfinite_bits |= (bits & 0x7f800000u) == 0x7f800000u;
        m[i] = b1 * m[i] + (1 - b1) * gr[i];
        v[i] = b2 * v[i] + (1 - b2) * gr[i] * gr[i];
        x[i] -= lr[c] * (m[i] * c1) / (std::sqrt(v[i] * c2) + e);
      }
    }
    if (nonfinite_bits != 0 && nonfinite.empty()) nonfinite = p.name;
  }
  return nonfinite;
}

void Adam::KeepRows(const std::vector<uint8_t>& keep) {
  for (auto& [name, s] : state_) {
    if (s.m.empty()) continue;
    std::vector<ParamBlock> views = {{name + ".m", &s.m, s.width}, {name + ".v", &s.v, s.width}};
    mgsr::KeepRows(views, keep);
  }
}

void Adam::AppendZeroRows(size_t count) {
  for (auto& [name, s] : state_) {
    if (s.m.empty()) continue;
    s.m.resize(s.m.size() + count * s.width, 0.0f);
    s.v.resize(s.v.size() + count * s.width, 0.0f);
  }
}

void Adam::ResetBlock(const std::string& name) {
  auto it = state_.find(name);
  if (it == state_.end()) return;
  std::fill(it->second.m.begin(), it->second.m.end(), 0.0f);
  std::fill(it->second.v.begin(), it->second.v.end(), 0.0f);
}

}  // namespace mgsr
