#include "solvers/adam.h"

#include <glog/logging.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace mgsr {
namespace {

// Subnormal floats. An entry whose gradient stays zero (a primitive the views do not see, a
// colour band that does not matter) decays its first moment by beta1 per step, and after about
// 700 such steps it is subnormal: x86 arithmetic on subnormals takes a microcode assist, and the
// moment never reaches zero (0.9 x the smallest subnormal rounds back to it). Measured on 4M
// entries with zero gradients, one Adam step with 2 threads: 12 ms until step 600, 470 ms from
// step 800. So every kFlushInterval steps moments below kFlushMoment are set to zero: between
// two flushes a moment shrinks by at most 0.9^64 ~ 1e-3, so it never gets near the subnormal
// range (below 1.2e-38). A flushed entry's step would have been below rate x 1e-30 / eps =
// rate x 1e-15. A pass every 64 steps costs far less than a test per entry in every step (the
// update loop is ~30% slower with one).
constexpr int64_t kFlushInterval = 64;
constexpr float kFlushMoment = 1e-30f;
// Blocks from this many entries are updated on all threads: a model's small blocks (positions,
// scales, rotations, opacities; 270k entries in all for 25k Gaussians) must not run on one thread
// while the others wait.
constexpr int64_t kParallelFrom = 16384;

void FlushTinyMoments(std::vector<float>* m, std::vector<float>* v) {
  const int64_t n = static_cast<int64_t>(m->size());
  float* pm = m->data();
  float* pv = v->data();
#pragma omp parallel for schedule(static) if (n >= kParallelFrom)
  for (int64_t i = 0; i < n; ++i) {
    if (std::fabs(pm[i]) < kFlushMoment) pm[i] = 0.0f;
    if (pv[i] < kFlushMoment) pv[i] = 0.0f;
  }
}

}  // namespace

std::string Adam::Step(const std::vector<ParamBlock>& params, const std::vector<ParamBlock>& grads,
                       const LearningRates& learning_rates) {
  std::vector<float>& rates = rates_;
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
#pragma omp parallel for schedule(static) reduction(| : nonfinite_bits) if (n >= kParallelFrom)
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
    if (s.step % kFlushInterval == 0) FlushTinyMoments(&s.m, &s.v);
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

void Adam::ZeroRows(const std::vector<int>& rows) {
  for (auto& [name, s] : state_) {
    if (s.m.empty()) continue;
    for (int r : rows) {
      const size_t begin = static_cast<size_t>(r) * s.width;
      std::fill(s.m.begin() + begin, s.m.begin() + begin + s.width, 0.0f);
      std::fill(s.v.begin() + begin, s.v.begin() + begin + s.width, 0.0f);
    }
  }
}

}  // namespace mgsr
