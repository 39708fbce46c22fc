#include "mgsr/render/sh.h"

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "mgsr/render/simd16.h"

namespace mgsr {
namespace {

constexpr float kC0 = 0.28209479177387814f;
constexpr float kC1 = 0.4886025119029199f;
constexpr float kC2[5] = {1.0925484305920792f, -1.0925484305920792f, 0.31539156525252005f,
                          -1.0925484305920792f, 0.5462742152960396f};
constexpr float kC3[7] = {-0.5900435899266435f, 2.890611442640554f,   -0.4570457994644658f,
                          0.3731763325901154f,  -0.4570457994644658f, 1.445305721320277f,
                          -0.5900435899266435f};

}  // namespace

void ShBasis(int degree, float x, float y, float z, float b[kMaxShCoeffs]) {
  b[0] = kC0;
  if (degree < 1) return;
  b[1] = -kC1 * y;
  b[2] = kC1 * z;
  b[3] = -kC1 * x;
  if (degree < 2) return;
  const float xx = x * x, yy = y * y, zz = z * z;
  b[4] = kC2[0] * x * y;
  b[5] = kC2[1] * y * z;
  b[6] = kC2[2] * (2 * zz - xx - yy);
  b[7] = kC2[3] * x * z;
  b[8] = kC2[4] * (xx - yy);
  if (degree < 3) return;
  b[9] = kC3[0] * y * (3 * xx - yy);
  b[10] = kC3[1] * x * y * z;
  b[11] = kC3[2] * y * (4 * zz - xx - yy);
  b[12] = kC3[3] * z * (2 * zz - 3 * xx - 3 * yy);
  b[13] = kC3[4] * x * (4 * zz - xx - yy);
  b[14] = kC3[5] * z * (xx - yy);
  b[15] = kC3[6] * x * (xx - 3 * yy);
}

void ShBasisWithGradient(int degree, const float d[3], float b[kMaxShCoeffs],
                         float g[kMaxShCoeffs][3]) {
  ShBasis(degree, d, b);
  const float x = d[0], y = d[1], z = d[2];
  auto set = [&](int k, float gx, float gy, float gz) {
    g[k][0] = gx;
    g[k][1] = gy;
    g[k][2] = gz;
  };
  set(0, 0, 0, 0);
  if (degree < 1) return;
  set(1, 0, -kC1, 0);
  set(2, 0, 0, kC1);
  set(3, -kC1, 0, 0);
  if (degree < 2) return;
  const float xx = x * x, yy = y * y, zz = z * z;
  set(4, kC2[0] * y, kC2[0] * x, 0);
  set(5, 0, kC2[1] * z, kC2[1] * y);
  set(6, -2 * kC2[2] * x, -2 * kC2[2] * y, 4 * kC2[2] * z);
  set(7, kC2[3] * z, 0, kC2[3] * x);
  set(8, 2 * kC2[4] * x, -2 * kC2[4] * y, 0);
  if (degree < 3) return;
  set(9, 6 * kC3[0] * x * y, kC3[0] * (3 * xx - 3 * yy), 0);
  set(10, kC3[1] * y * z, kC3[1] * x * z, kC3[1] * x * y);
  set(11, -2 * kC3[2] * x * y, kC3[2] * (4 * zz - xx - 3 * yy), 8 * kC3[2] * y * z);
  set(12, -6 * kC3[3] * x * z, -6 * kC3[3] * y * z, kC3[3] * (6 * zz - 3 * xx - 3 * yy));
  set(13, kC3[4] * (4 * zz - 3 * xx - yy), -2 * kC3[4] * x * y, 8 * kC3[4] * x * z);
  set(14, 2 * kC3[5] * x * z, -2 * kC3[5] * y * z, kC3[5] * (xx - yy));
  set(15, kC3[6] * (3 * xx - 3 * yy), -6 * kC3[6] * x * y, 0);
}

namespace {

// Calls f with the coefficient count n = (degree + 1)^2 as a compile-time constant
// (std::integral_constant), the one place that picks the counts the FromBasis loops are built for.
template <class F>
void WithCoefficientCount(int n, F&& f) {
  switch (n) {
    case 1:
      return f(std::integral_constant<int, 1>{});
    case 4:
      return f(std::integral_constant<int, 4>{});
    case 9:
      return f(std::integral_constant<int, 9>{});
    default:
      return f(std::integral_constant<int, 16>{});
  }
}

#if defined(__AVX512F__) && defined(__FMA__)
// Degree 3 (16 coefficient rows, the count training spends nearly all its steps at) in vectors:
// the 48 floats of a row block as three 16-lane vectors. Each lane computes what the scalar loops
// below compute, in the same order, with the multiply-adds GCC forms there spelled out, so the
// results are the same to the bit (the trained-render digests do not move); the scalar loops took
// one instruction per coefficient and channel, and were most of the SH cost in `perf`.
using simd::F16;
using simd::F4;

inline F4 Fma4(F4 a, F4 b, F4 c) { return _mm_fmadd_ps(a, b, c); }

// x[3k + c] for k < 16, from x = [x0 | x1 | x2].
inline F16 Channel0(F16 x0, F16 x1, F16 x2) {
  const F16 t =
      __builtin_shufflevector(x0, x1, 0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 0, 0, 0, 0, 0);
  return __builtin_shufflevector(t, x2, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 17, 20, 23, 26, 29);
}
inline F16 Channel1(F16 x0, F16 x1, F16 x2) {
  const F16 t =
      __builtin_shufflevector(x0, x1, 1, 4, 7, 10, 13, 16, 19, 22, 25, 28, 31, 0, 0, 0, 0, 0);
  return __builtin_shufflevector(t, x2, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 18, 21, 24, 27, 30);
}
inline F16 Channel2(F16 x0, F16 x1, F16 x2) {
  const F16 t =
      __builtin_shufflevector(x0, x1, 2, 5, 8, 11, 14, 17, 20, 23, 26, 29, 0, 0, 0, 0, 0, 0);
  return __builtin_shufflevector(t, x2, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 19, 22, 25, 28, 31);
}

// sum_k a_k b_k over 16 rows in the scalar loops' order: four partial sums (k mod 4), each a
// multiply-add chain from zero over k = r, r + 4, r + 8, r + 12, then (p0 + p1) + (p2 + p3).
inline float SumOfProducts16(F16 a, F16 b) {
  const auto quarter = [](F16 v, auto q) {
    constexpr int o = 4 * decltype(q)::value;
    return __builtin_shufflevector(v, v, o, o + 1, o + 2, o + 3);
  };
  F4 acc = Fma4(quarter(a, std::integral_constant<int, 0>{}),
                quarter(b, std::integral_constant<int, 0>{}), F4{});
  acc = Fma4(quarter(a, std::integral_constant<int, 1>{}),
             quarter(b, std::integral_constant<int, 1>{}), acc);
  acc = Fma4(quarter(a, std::integral_constant<int, 2>{}),
             quarter(b, std::integral_constant<int, 2>{}), acc);
  acc = Fma4(quarter(a, std::integral_constant<int, 3>{}),
             quarter(b, std::integral_constant<int, 3>{}), acc);
  return (acc[0] + acc[1]) + (acc[2] + acc[3]);
}

void EvalFromBasis16(const float* b, const float* coeffs, float rgb[3], uint8_t clamped[3]) {
  const F16 basis = simd::Load<F16>(b);
  const F16 x0 = simd::Load<F16>(coeffs), x1 = simd::Load<F16>(coeffs + 16),
            x2 = simd::Load<F16>(coeffs + 32);
  const F16 channel[3] = {Channel0(x0, x1, x2), Channel1(x0, x1, x2), Channel2(x0, x1, x2)};
  for (int c = 0; c < 3; ++c) {
    const float v = 0.5f + SumOfProducts16(basis, channel[c]);
    clamped[c] = v < 0.0f;
    rgb[c] = v < 0.0f ? 0.0f : v;
  }
}

// The kWrite backward for 16 rows.
void WriteBackwardFromBasis16(const float* b, const float (*g)[3], const float* coeffs,
                              const float dc[3], float* d_coeffs, float d_dir[3]) {
  const F16 basis = simd::Load<F16>(b);
  const F16 dc_lanes = {dc[0], dc[1], dc[2]};
  // d coeffs[3k + c] = 0 + b_k dc_c.
  const F16 b0 =
      __builtin_shufflevector(basis, basis, 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5);
  const F16 b1 =
      __builtin_shufflevector(basis, basis, 5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8, 9, 9, 9, 10, 10);
  const F16 b2 = __builtin_shufflevector(basis, basis, 10, 11, 11, 11, 12, 12, 12, 13, 13, 13, 14,
                                         14, 14, 15, 15, 15);
  const F16 d0 =
      __builtin_shufflevector(dc_lanes, dc_lanes, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0);
  const F16 d1 =
      __builtin_shufflevector(dc_lanes, dc_lanes, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1);
  const F16 d2 =
      __builtin_shufflevector(dc_lanes, dc_lanes, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2);
  simd::Store(d_coeffs, simd::Fma(b0, d0, F16{}));
  simd::Store(d_coeffs + 16, simd::Fma(b1, d1, F16{}));
  simd::Store(d_coeffs + 32, simd::Fma(b2, d2, F16{}));
  // s_k = sum_c coeffs[k][c] dc_c, as GCC fuses the scalar expression: (c1 dc1 + c0 dc0) + c2 dc2.
  const F16 x0 = simd::Load<F16>(coeffs), x1 = simd::Load<F16>(coeffs + 16),
            x2 = simd::Load<F16>(coeffs + 32);
  const F16 s = simd::Fma(
      Channel2(x0, x1, x2), simd::Splat<F16>(dc[2]),
      simd::Fma(Channel0(x0, x1, x2), simd::Splat<F16>(dc[0]), Channel1(x0, x1, x2) * dc[1]));
  // d dir_c += sum_k s_k g[k][c].
  const float* gf = &g[0][0];
  const F16 y0 = simd::Load<F16>(gf), y1 = simd::Load<F16>(gf + 16), y2 = simd::Load<F16>(gf + 32);
  d_dir[0] += SumOfProducts16(s, Channel0(y0, y1, y2));
  d_dir[1] += SumOfProducts16(s, Channel1(y0, y1, y2));
  d_dir[2] += SumOfProducts16(s, Channel2(y0, y1, y2));
}
#endif

// The sums over coefficients run in four interleaved partial sums (k mod 4): sixteen dependent
// multiply-adds per channel would otherwise be one long latency chain per primitive. The count is
// a template argument so the loops unroll and the twelve partial sums stay in registers (with a
// run-time count they lived on the stack: a store-to-load chain per coefficient).
template <int N>
void EvalFromBasis(const float* __restrict b, const float* __restrict coeffs, float rgb[3],
                   uint8_t clamped[3]) {
#if defined(__AVX512F__) && defined(__FMA__)
  if constexpr (N == 16) return EvalFromBasis16(b, coeffs, rgb, clamped);
#endif
  float acc[4][3] = {};
#pragma GCC unroll 16
  for (int k = 0; k < N; ++k) {
    for (int c = 0; c < 3; ++c) acc[k & 3][c] += b[k] * coeffs[k * 3 + c];
  }
  for (int c = 0; c < 3; ++c) {
    const float v = 0.5f + ((acc[0][c] + acc[1][c]) + (acc[2][c] + acc[3][c]));
    clamped[c] = v < 0.0f;
    rgb[c] = v < 0.0f ? 0.0f : v;
  }
}

}  // namespace

void EvalShColorFromBasis(int n, const float b[kMaxShCoeffs], const float* coeffs, float rgb[3],
                          uint8_t clamped[3]) {
  WithCoefficientCount(n, [&](auto count) { EvalFromBasis<count()>(b, coeffs, rgb, clamped); });
}

void EvalShColor(int degree, const float* coeffs, const float dir[3], float rgb[3],
                 uint8_t clamped[3]) {
  float b[kMaxShCoeffs];
  ShBasis(degree, dir, b);
  EvalShColorFromBasis((degree + 1) * (degree + 1), b, coeffs, rgb, clamped);
}

namespace {

// kWrite: d_coeffs = 0 + gradient, else d_coeffs += gradient (the same bits on a zeroed row).
// N as in EvalFromBasis.
template <bool kWrite, int N>
void ShColorBackwardFromBasis(const float* __restrict b, const float (*__restrict g)[3],
                              const float* __restrict coeffs, const uint8_t clamped[3],
                              const float d_rgb[3], float* __restrict d_coeffs, float d_dir[3]) {
  const float dc[3] = {clamped[0] ? 0.0f : d_rgb[0], clamped[1] ? 0.0f : d_rgb[1],
                       clamped[2] ? 0.0f : d_rgb[2]};
#if defined(__AVX512F__) && defined(__FMA__)
  if constexpr (kWrite && N == 16)
    return WriteBackwardFromBasis16(b, g, coeffs, dc, d_coeffs, d_dir);
#endif
  float acc[4][3] = {};
#pragma GCC unroll 16
  for (int k = 0; k < N; ++k) {
    const float s = coeffs[k * 3] * dc[0] + coeffs[k * 3 + 1] * dc[1] + coeffs[k * 3 + 2] * dc[2];
    for (int c = 0; c < 3; ++c) {
      const float before = kWrite ? 0.0f : d_coeffs[k * 3 + c];
      d_coeffs[k * 3 + c] = before + b[k] * dc[c];
    }
    for (int c = 0; c < 3; ++c) acc[k & 3][c] += s * g[k][c];
  }
  for (int c = 0; c < 3; ++c) d_dir[c] += (acc[0][c] + acc[1][c]) + (acc[2][c] + acc[3][c]);
}

template <bool kWrite>
void ShColorBackwardFromBasis(int n, const float b[kMaxShCoeffs], const float g[kMaxShCoeffs][3],
                              const float* coeffs, const uint8_t clamped[3], const float d_rgb[3],
                              float* d_coeffs, float d_dir[3]) {
  WithCoefficientCount(n, [&](auto count) {
    ShColorBackwardFromBasis<kWrite, count()>(b, g, coeffs, clamped, d_rgb, d_coeffs, d_dir);
  });
}

}  // namespace

void EvalShColorBackwardFromBasis(int n, const float b[kMaxShCoeffs],
                                  const float g[kMaxShCoeffs][3], const float* coeffs,
                                  const uint8_t clamped[3], const float d_rgb[3], float* d_coeffs,
                                  float d_dir[3]) {
  ShColorBackwardFromBasis<false>(n, b, g, coeffs, clamped, d_rgb, d_coeffs, d_dir);
}

void WriteShColorBackwardFromBasis(int n, const float b[kMaxShCoeffs],
                                   const float g[kMaxShCoeffs][3], const float* coeffs,
                                   const uint8_t clamped[3], const float d_rgb[3], float* d_coeffs,
                                   float d_dir[3]) {
  ShColorBackwardFromBasis<true>(n, b, g, coeffs, clamped, d_rgb, d_coeffs, d_dir);
}

void WriteShRowBackward(int n, const float b[kMaxShCoeffs], const float g[kMaxShCoeffs][3],
                        const float* coeffs, const uint8_t clamped[3], const float d_rgb[3],
                        size_t row_floats, float* d_row, float d_dir[3]) {
  WriteShColorBackwardFromBasis(n, b, g, coeffs, clamped, d_rgb, d_row, d_dir);
  std::fill(d_row + 3 * n, d_row + row_floats, 0.0f);
}

void EvalShColorBackward(int degree, const float* coeffs, const float dir[3],
                         const uint8_t clamped[3], const float d_rgb[3], float* d_coeffs,
                         float d_dir[3]) {
  float b[kMaxShCoeffs], g[kMaxShCoeffs][3];
  ShBasisWithGradient(degree, dir, b, g);
  d_dir[0] = d_dir[1] = d_dir[2] = 0;
  EvalShColorBackwardFromBasis((degree + 1) * (degree + 1), b, g, coeffs, clamped, d_rgb, d_coeffs,
                               d_dir);
}

void NormalizeBackward(const float v[3], const float d_dir[3], float d_v[3]) {
  const float len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  const float inv = len > 0 ? 1.0f / len : 0.0f;
  const float u[3] = {v[0] * inv, v[1] * inv, v[2] * inv};
  const float dot = u[0] * d_dir[0] + u[1] * d_dir[1] + u[2] * d_dir[2];
  for (int k = 0; k < 3; ++k) d_v[k] = (d_dir[k] - u[k] * dot) * inv;
}

}  // namespace mgsr
