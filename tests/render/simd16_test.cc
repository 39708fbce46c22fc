#include "mgsr/render/simd16.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

// The suite's name, so that simd16_portable_test.cc can compile the same checks a second time.
#ifndef MGSR_SIMD16_SUITE
#define MGSR_SIMD16_SUITE Simd16
#endif

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

TEST(MGSR_SIMD16_SUITE, SumEachIsSumToTheBit16Lanes) {
  for (uint32_t seed = 1; seed <= 50; ++seed) ExpectSumEachMatchesSum<F16>(seed);
}

TEST(MGSR_SIMD16_SUITE, SumEachIsSumToTheBit8Lanes) {
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

TEST(MGSR_SIMD16_SUITE, StoreMaskedWritesOnlyMaskedLanes) {
  ExpectStoreMaskedWritesOnlyMaskedLanes<F16>();
  ExpectStoreMaskedWritesOnlyMaskedLanes<F8>();
}

// Exp gives the same bits at every width: the 16- and 8-lane forms use the instruction set's floor
// and scale instructions where the build has them, the 4-lane form the portable ones. Over a dense
// sweep of the rasterizers' argument range [-80, 0] plus the range ends.
TEST(MGSR_SIMD16_SUITE, ExpIsTheSameAtEveryWidth) {
  std::vector<float> xs = {0.0f, -0.0f, -80.0f, -1e-30f, -0.5f, -1.0f, -69.31472f};
  for (int i = 0; i <= 400000; ++i) xs.push_back(-80.0f * i / 400000.0f);
  int checked = 0;
  for (size_t i = 0; i + 16 <= xs.size(); i += 16) {
    F16 x16;
    for (int l = 0; l < 16; ++l) x16[l] = xs[i + l];
    const F16 e16 = Exp(x16);
    F8 a8, b8;
    F4 q4[4];
    for (int l = 0; l < 8; ++l) {
      a8[l] = xs[i + l];
      b8[l] = xs[i + 8 + l];
    }
    for (int q = 0; q < 4; ++q)
      for (int l = 0; l < 4; ++l) q4[q][l] = xs[i + 4 * q + l];
    const F8 ea = Exp(a8), eb = Exp(b8);
    for (int l = 0; l < 16; ++l) {
      const float want = Exp(q4[l / 4])[l % 4];
      const float got8 = l < 8 ? ea[l] : eb[l - 8];
      ASSERT_EQ(std::memcmp(&e16[l], &want, 4), 0) << "x " << xs[i + l];
      ASSERT_EQ(std::memcmp(&got8, &want, 4), 0) << "x " << xs[i + l];
      // And it is exp: within a few units in the last place.
      ASSERT_NEAR(want, std::exp(xs[i + l]), 4e-7f * std::exp(xs[i + l])) << "x " << xs[i + l];
      ++checked;
    }
  }
  EXPECT_GE(checked, 400000);
}

TEST(MGSR_SIMD16_SUITE, FloorAndScaleAreExact) {
  for (int i = -2000; i <= 2000; ++i) {
    const float f = i * 0.0625f - 0.03125f * (i % 3);
    F16 v16 = Splat<F16>(f);
    F8 v8 = Splat<F8>(f);
    EXPECT_EQ(Floor(v16)[3], std::floor(f)) << f;
    EXPECT_EQ(Floor(v8)[5], std::floor(f)) << f;
  }
  for (int t = -126; t <= 127; ++t) {
    const float y = 1.2345678f;
    EXPECT_EQ(ScaleByPowerOfTwo(Splat<F16>(y), Splat<F16>(static_cast<float>(t)))[7],
              std::ldexp(y, t))
        << t;
    EXPECT_EQ(ScaleByPowerOfTwo(Splat<F8>(y), Splat<F8>(static_cast<float>(t)))[2],
              std::ldexp(y, t))
        << t;
  }
}

// Fma / Fms round once where the build has FMA instructions (the rasterizers' two passes rely on
// the same fusing), and are the plain expression otherwise.
TEST(MGSR_SIMD16_SUITE, FmaAndFmsRoundOnce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  for (int trial = 0; trial < 200; ++trial) {
    F16 a, b, c;
    F8 a8, b8, c8;
    for (int l = 0; l < 16; ++l) {
      a[l] = u(rng);
      b[l] = u(rng);
      c[l] = u(rng);
    }
    for (int l = 0; l < 8; ++l) {
      a8[l] = a[l];
      b8[l] = b[l];
      c8[l] = c[l];
    }
    const F16 f = Fma(a, b, c), g = Fms(a, b, c);
    const F8 f8 = Fma(a8, b8, c8), g8 = Fms(a8, b8, c8);
    for (int l = 0; l < 16; ++l) {
#if defined(__FMA__)
      EXPECT_EQ(f[l], std::fma(a[l], b[l], c[l]));
      EXPECT_EQ(g[l], std::fma(a[l], b[l], -c[l]));
#else
      EXPECT_NEAR(f[l], a[l] * b[l] + c[l], 1e-6f);
      EXPECT_NEAR(g[l], a[l] * b[l] - c[l], 1e-6f);
#endif
    }
    for (int l = 0; l < 8; ++l) {
#if defined(__FMA__)
      EXPECT_EQ(f8[l], std::fma(a8[l], b8[l], c8[l]));
      EXPECT_EQ(g8[l], std::fma(a8[l], b8[l], -c8[l]));
#else
      EXPECT_NEAR(f8[l], a8[l] * b8[l] + c8[l], 1e-6f);
      EXPECT_NEAR(g8[l], a8[l] * b8[l] - c8[l], 1e-6f);
#endif
    }
  }
}

// And a different pairing would be caught: the sum of the lanes in index order differs from Sum
// for some of these inputs (else the test above could not fail).
TEST(MGSR_SIMD16_SUITE, PairingMattersForTheseInputs) {
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

// Every lane operation the pixel loops use, lane by lane against the scalar operation, at both
// widths: where the build has no AVX-512 a 16-lane vector is a pair of 8-lane halves with
// operators of its own (simd16.h), which must act as the 64-byte vector would.
template <class V>
void ExpectLaneOperationsAreScalar(uint32_t seed) {
  constexpr int L = kLanesOf<V>;
  using M = MaskOf<V>;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-3.0f, 3.0f);
  V a, b;
  for (int l = 0; l < L; ++l) {
    a[l] = u(rng);
    b[l] = l % 5 == 0 ? a[l] : u(rng);  // some ties for the comparisons
  }
  const float s = 0.75f;
  const M lt = a<b, le = a <= b, gt = a> s, ge = s >= b, eq = a == b, ne = a != b;
  const M both = lt & ge, either = lt | gt, odd = lt ^ gt, neither = ~either;
  const V sum = a + b, diff = a - s, prod = s * b, quot = a / b, neg = -a;
  V acc = a;
  acc += b;
  acc *= b;
  acc -= a;
  const V sel = IfElse(lt, a, b), sel2 = Select(gt, a, b), low = Min(a, b), high = Max(a, b);
  const V mag = Abs(a), kept = Masked(le, a), fl = Floor(a * 4.0f), lanes = Lanes<V>();
  const V fma = Fma(a, b, Splat<V>(s));
  for (int l = 0; l < L; ++l) {
    EXPECT_EQ(lt[l], a[l] < b[l] ? -1 : 0) << l;
    EXPECT_EQ(le[l], a[l] <= b[l] ? -1 : 0) << l;
    EXPECT_EQ(gt[l], a[l] > s ? -1 : 0) << l;
    EXPECT_EQ(ge[l], s >= b[l] ? -1 : 0) << l;
    EXPECT_EQ(eq[l], a[l] == b[l] ? -1 : 0) << l;
    EXPECT_EQ(ne[l], a[l] != b[l] ? -1 : 0) << l;
    EXPECT_EQ(both[l], lt[l] & ge[l]) << l;
    EXPECT_EQ(either[l], lt[l] | gt[l]) << l;
    EXPECT_EQ(odd[l], lt[l] ^ gt[l]) << l;
    EXPECT_EQ(neither[l], ~either[l]) << l;
    EXPECT_EQ(sum[l], a[l] + b[l]) << l;
    EXPECT_EQ(diff[l], a[l] - s) << l;
    EXPECT_EQ(prod[l], s * b[l]) << l;
    EXPECT_EQ(quot[l], a[l] / b[l]) << l;
    EXPECT_EQ(neg[l], -a[l]) << l;
    EXPECT_EQ(acc[l], (a[l] + b[l]) * b[l] - a[l]) << l;
    EXPECT_EQ(sel[l], a[l] < b[l] ? a[l] : b[l]) << l;
    EXPECT_EQ(sel2[l], a[l] > s ? a[l] : b[l]) << l;
    EXPECT_EQ(low[l], std::min(a[l], b[l])) << l;
    EXPECT_EQ(high[l], std::max(a[l], b[l])) << l;
    EXPECT_EQ(mag[l], std::abs(a[l])) << l;
    EXPECT_EQ(kept[l], a[l] <= b[l] ? a[l] : 0.0f) << l;
    EXPECT_EQ(fl[l], std::floor(a[l] * 4.0f)) << l;
    EXPECT_EQ(lanes[l], static_cast<float>(l)) << l;
    EXPECT_NEAR(fma[l], a[l] * b[l] + s, 1e-5f) << l;
  }
  // Any sees a single set lane wherever it is.
  for (int l = 0; l < L; ++l) {
    M one{};
    one[l] = -1;
    EXPECT_TRUE(Any(one)) << l;
  }
  EXPECT_FALSE(Any(M{}));
}

TEST(MGSR_SIMD16_SUITE, LaneOperationsAreScalar16Lanes) {
  for (uint32_t seed = 1; seed <= 20; ++seed) ExpectLaneOperationsAreScalar<F16>(seed);
}

TEST(MGSR_SIMD16_SUITE, LaneOperationsAreScalar8Lanes) {
  for (uint32_t seed = 1; seed <= 20; ++seed) ExpectLaneOperationsAreScalar<F8>(seed);
}

// Whole numbers below 2^24 to float rows and back (the last-blended indices), every lane.
TEST(MGSR_SIMD16_SUITE, UintRowsRoundTrip) {
  U16 u;
  for (int l = 0; l < 16; ++l) u[l] = (l == 3 ? (1u << 24) - 1 : 0u) + 977u * l * l;
  const F16 f = ToFloat(u);
  const U16 back = ToUint(f);
  for (int l = 0; l < 16; ++l) {
    EXPECT_EQ(f[l], static_cast<float>(u[l])) << l;
    EXPECT_EQ(back[l], u[l]) << l;
  }
}

}  // namespace
}  // namespace mgsr::simd
