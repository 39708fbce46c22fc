// Rng: a seeded generator whose outputs do not depend on the standard library's distribution code,
// so the same seed gives the same scene and the same training run with any compiler.
#pragma once

#include <cmath>
#include <cstdint>

namespace mgsr {

class Rng {
 public:
  explicit Rng(uint64_t seed = 0) : state_(seed * 0x9E3779B97F4A7C15ull + 0x632BE59BD9B4E019ull) {}

  // splitmix64: small, fast, and good enough for sampling (not for cryptography).
  uint64_t NextU64() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double Uniform() { return (NextU64() >> 11) * (1.0 / 9007199254740992.0); }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // Uniform integer in [0, n).
  uint64_t UniformInt(uint64_t n) { return n == 0 ? 0 : NextU64() % n; }
  // Standard normal (Box-Muller, one value per call for simplicity).
  double Normal() {
    double u1 = Uniform();
    if (u1 < 1e-300) u1 = 1e-300;
    const double u2 = Uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
  double Normal(double mean, double stddev) { return mean + stddev * Normal(); }

  // The whole generator state, for checkpoints.
  uint64_t state() const { return state_; }
  void set_state(uint64_t s) { state_ = s; }

 private:
  uint64_t state_;
};

}  // namespace mgsr
