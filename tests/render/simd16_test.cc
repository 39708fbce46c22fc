#include "mgsr/render/simd16.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

namespace mgsr::simd {
namespace {

// SumEach must give each vector's Sum to the bit: the backward passes' gradients (and every
// figure measured with them) depend on the order of the additions.
template <class V>
void ExpectSumEachMatchesSum(uint32_t seed) {
  std::mt19937 rng(seed);
  // Values of mixed sign and magnitude, so a different pairing would round differently.
  std::uniform_real_distribution<float> mantissa(-1.0f, 1.0f);
  std::uniform_int_distribution<int> exponent(-20, 20);
  V v[16];
  for (V& x : v)
    for (int l = 0; l < kLanesOf<V>; ++l) x[l] = std::ldexp(mantissa(rng), exponent(rng));
  float got[16];
  SumEach(v, got);
  for (int i = 0; i < 16; ++i) {
    const float want = Sum(v[i]);
    uint32_t a, b;
    std::memcpy(&a, &got[i], 4);
    std::memcpy(&b, &want, 4);
    EXPECT_EQ(a, b) << "vector " << i << ": " << got[i] << " vs " << want;
  }
}

TEST(Simd16, SumEachIsSumToTheBit16Lanes) {
  for (uint32_t seed = 1; seed <= 50; ++seed) ExpectSumEachMatchesSum<F16>(seed);
}

TEST(Simd16, SumEachIsSumToTheBit8Lanes) {
  for (uint32_t seed = 1; seed <= 50; ++seed) ExpectSumEachMatchesSum<F8>(seed);
}

// StoreMasked writes the masked lanes and leaves the others (and the memory around) untouched.
template <class V>
void ExpectStoreMaskedWritesOnlyMaskedLanes() {
  constexpr int L = kLanesOf<V>;
  float memory[L + 2];
  for (int i = 0; i < L + 2; ++i) memory[i] = -1.0f - i;
  V v;
  MaskOf<V> mask;
  for (int l = 0; l < L; ++l) {
    v[l] = 100.0f + l;
    mask[l] = (l % 3 == 1) ? -1 : 0;
  }
  StoreMasked(memory + 1, mask, v);
  EXPECT_EQ(memory[0], -1.0f);
  EXPECT_EQ(memory[L + 1], -2.0f - L);
  for (int l = 0; l < L; ++l)
    EXPECT_EQ(memory[1 + l], l % 3 == 1 ? 100.0f + l : -2.0f - l) << "lane " << l;
}

TEST(Simd16, StoreMaskedWritesOnlyMaskedLanes) {
  ExpectStoreMaskedWritesOnlyMaskedLanes<F16>();
  ExpectStoreMaskedWritesOnlyMaskedLanes<F8>();
}

// And a different pairing would be caught: the sum of the lanes in index order differs from Sum
// for some of these inputs (else the test above could not fail).
TEST(Simd16, PairingMattersForTheseInputs) {
  int differs = 0;
  for (uint32_t seed = 1; seed <= 50; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> mantissa(-1.0f, 1.0f);
    std::uniform_int_distribution<int> exponent(-20, 20);
    F16 x;
    for (int l = 0; l < 16; ++l) x[l] = std::ldexp(mantissa(rng), exponent(rng));
    float sequential = 0;
    for (int l = 0; l < 16; ++l) sequential += x[l];
    differs += sequential != Sum(x);
  }
  EXPECT_GT(differs, 0);
}

}  // namespace
}  // namespace mgsr::simd
