// Float vectors of 16 lanes (one 16-pixel tile row) and 8 lanes (half a row, for primitives whose
// footprint in a tile is at most 8 columns wide) with GCC/Clang vector extensions: the compiler
// maps them onto AVX-512, AVX2 or SSE registers, whichever the build targets. Only what the
// rasterizers need: arithmetic comes from the extension, plus masks, select, min/max, abs, loads
// and a branch-free exp. Every helper is generic over the width, so a pixel loop written once as a
// template runs at either width.
#pragma once

#include <cstdint>
#include <cstring>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace mgsr::simd {

typedef float F16 __attribute__((vector_size(64)));
typedef int32_t I16 __attribute__((vector_size(64)));  // lane masks: -1 (true) or 0
typedef uint32_t U16 __attribute__((vector_size(64)));
typedef float F8 __attribute__((vector_size(32)));
typedef int32_t I8 __attribute__((vector_size(32)));
typedef float F4 __attribute__((vector_size(16)));
typedef int32_t I4 __attribute__((vector_size(16)));

// The mask type of a float vector type (what its comparisons return).
template <class V>
using MaskOf = decltype(V{} < V{});
template <class V>
constexpr int kLanesOf = static_cast<int>(sizeof(V) / sizeof(float));

// Unaligned loads and stores (memcpy compiles to one vector move).
template <class V = F16>
inline V Load(const float* p) {
  V v;
  std::memcpy(&v, p, sizeof(V));
  return v;
}
template <class V>
inline void Store(float* p, V v) {
  std::memcpy(p, &v, sizeof(V));
}
// Stores the lanes of `v` where `mask` is set, leaving the others in memory as they are: one
// masked store where the build targets AVX-512 (no load of the old values), a blend otherwise.
// (The intrinsics take these vector types as they are: same size, same element type.)
inline void StoreMasked(float* p, I16 mask, F16 v) {
#if defined(__AVX512F__)
  _mm512_mask_storeu_ps(p, _mm512_test_epi32_mask((__m512i)mask, (__m512i)mask), v);
#else
  Store(p, mask ? v : Load<F16>(p));
#endif
}
inline void StoreMasked(float* p, I8 mask, F8 v) {
#if defined(__AVX512F__) && defined(__AVX512VL__)
  _mm256_mask_storeu_ps(p, _mm256_test_epi32_mask((__m256i)mask, (__m256i)mask), v);
#else
  Store(p, mask ? v : Load<F8>(p));
#endif
}

template <class V = F16>
inline V Splat(float v) {
  return V{} + v;
}
template <class V = F16>
inline V Lanes() {
  V v{};
  for (int i = 0; i < kLanesOf<V>; ++i) v[i] = static_cast<float>(i);
  return v;
}

template <class V>
inline V Select(MaskOf<V> mask, V a, V b) {
  return mask ? a : b;
}
template <class V>
inline V Min(V a, V b) {
  return a < b ? a : b;
}
template <class V>
inline V Max(V a, V b) {
  return a > b ? a : b;
}
template <class V>
inline V Abs(V a) {
  return a < 0.0f ? -a : a;
}
template <class V>
inline V Masked(MaskOf<V> mask, V a) {
  return mask ? a : V{};
}

// a * b + c and a * b - c with one rounding, wherever they stand: the compiler fuses a multiply
// and an add only as the code around lets it, so where two passes must compute the same value to
// the bit, the fusing is spelled out. (Without FMA instructions: unfused, as the compiler does.)
inline F16 Fma(F16 a, F16 b, F16 c) {
#if defined(__AVX512F__)
  return _mm512_fmadd_ps(a, b, c);
#else
  return a * b + c;
#endif
}
inline F16 Fms(F16 a, F16 b, F16 c) {
#if defined(__AVX512F__)
  return _mm512_fmsub_ps(a, b, c);
#else
  return a * b - c;
#endif
}
inline F8 Fma(F8 a, F8 b, F8 c) {
#if defined(__FMA__)
  return _mm256_fmadd_ps(a, b, c);
#else
  return a * b + c;
#endif
}
inline F8 Fms(F8 a, F8 b, F8 c) {
#if defined(__FMA__)
  return _mm256_fmsub_ps(a, b, c);
#else
  return a * b - c;
#endif
}

// Horizontal reductions by halving (a few shuffles instead of dependent scalar adds).
inline float Sum(F4 v) { return (v[0] + v[2]) + (v[1] + v[3]); }
inline float Sum(F8 v) {
  F4 a, b;
  std::memcpy(&a, &v, sizeof(a));
  std::memcpy(&b, reinterpret_cast<const char*>(&v) + sizeof(a), sizeof(b));
  return Sum(a + b);
}
inline float Sum(F16 v) {
  F8 a, b;
  std::memcpy(&a, &v, sizeof(a));
  std::memcpy(&b, reinterpret_cast<const char*>(&v) + sizeof(a), sizeof(b));
  return Sum(a + b);
}

// The horizontal sums of 16 vectors at once: out[i] = Sum(v[i]) to the bit (every lane is added
// in the pairs Sum uses), but the halving steps of different vectors share their shuffles and
// adds: 16-lane vectors take 15 adds and 30 two-source shuffles for all 16 sums instead of about
// four of each per sum. For the per-primitive gradient sums that close each entry of the
// rasterizers' backward passes.
inline void SumEach(const F16 (&v)[16], float out[16]) {
  F16 p[8];  // [v[2i] lo8 + hi8 | v[2i+1] lo8 + hi8]
  for (int i = 0; i < 8; ++i)
    p[i] = __builtin_shufflevector(v[2 * i], v[2 * i + 1], 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19,
                                   20, 21, 22, 23) +
           __builtin_shufflevector(v[2 * i], v[2 * i + 1], 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26,
                                   27, 28, 29, 30, 31);
  F16 q[4];  // four vectors' lo4 + hi4 each
  for (int i = 0; i < 4; ++i)
    q[i] = __builtin_shufflevector(p[2 * i], p[2 * i + 1], 0, 1, 2, 3, 8, 9, 10, 11, 16, 17, 18, 19,
                                   24, 25, 26, 27) +
           __builtin_shufflevector(p[2 * i], p[2 * i + 1], 4, 5, 6, 7, 12, 13, 14, 15, 20, 21, 22,
                                   23, 28, 29, 30, 31);
  F16 r[2];  // eight vectors' (x0 + x2, x1 + x3) each
  for (int i = 0; i < 2; ++i)
    r[i] = __builtin_shufflevector(q[2 * i], q[2 * i + 1], 0, 1, 4, 5, 8, 9, 12, 13, 16, 17, 20, 21,
                                   24, 25, 28, 29) +
           __builtin_shufflevector(q[2 * i], q[2 * i + 1], 2, 3, 6, 7, 10, 11, 14, 15, 18, 19, 22,
                                   23, 26, 27, 30, 31);
  const F16 s = __builtin_shufflevector(r[0], r[1], 0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24,
                                        26, 28, 30) +
                __builtin_shufflevector(r[0], r[1], 1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25,
                                        27, 29, 31);
  Store(out, s);
}
inline void SumEach(const F8 (&v)[16], float out[16]) {
  for (int h = 0; h < 2; ++h) {
    F8 p[4];  // [v[2i] lo4 + hi4 | v[2i+1] lo4 + hi4]
    for (int i = 0; i < 4; ++i) {
      const F8 a = v[8 * h + 2 * i], b = v[8 * h + 2 * i + 1];
      p[i] = __builtin_shufflevector(a, b, 0, 1, 2, 3, 8, 9, 10, 11) +
             __builtin_shufflevector(a, b, 4, 5, 6, 7, 12, 13, 14, 15);
    }
    F8 r[2];  // four vectors' (x0 + x2, x1 + x3) each
    for (int i = 0; i < 2; ++i)
      r[i] = __builtin_shufflevector(p[2 * i], p[2 * i + 1], 0, 1, 4, 5, 8, 9, 12, 13) +
             __builtin_shufflevector(p[2 * i], p[2 * i + 1], 2, 3, 6, 7, 10, 11, 14, 15);
    const F8 s = __builtin_shufflevector(r[0], r[1], 0, 2, 4, 6, 8, 10, 12, 14) +
                 __builtin_shufflevector(r[0], r[1], 1, 3, 5, 7, 9, 11, 13, 15);
    Store(out + 8 * h, s);
  }
}

// Whether any lane of a mask is set: one test instruction where the build targets AVX / AVX-512
// (the rasterizers' per-row "does this row blend anything" branch), shuffles otherwise.
inline bool Any(I4 m) { return (m[0] | m[1] | m[2] | m[3]) != 0; }
inline bool Any(I8 mask) {
#if defined(__AVX__)
  __m256i v;
  std::memcpy(&v, &mask, sizeof(v));
  return !_mm256_testz_si256(v, v);
#else
  I4 a, b;
  std::memcpy(&a, &mask, sizeof(a));
  std::memcpy(&b, reinterpret_cast<const char*>(&mask) + sizeof(a), sizeof(b));
  return Any(a | b);
#endif
}
inline bool Any(I16 mask) {
#if defined(__AVX512F__)
  __m512i v;
  std::memcpy(&v, &mask, sizeof(v));
  return _mm512_test_epi32_mask(v, v) != 0;
#else
  I8 a, b;
  std::memcpy(&a, &mask, sizeof(a));
  std::memcpy(&b, reinterpret_cast<const char*>(&mask) + sizeof(a), sizeof(b));
  return Any(a | b);
#endif
}

// floor(f), exact for |f| < 2^31: one rounding instruction where the build has one (AVX / AVX-512),
// else truncation through int32 and a correction for negative non-integers.
template <class V>
inline V Floor(V f) {
  using I = MaskOf<V>;
  V t = __builtin_convertvector(__builtin_convertvector(f, I), V);  // truncates toward 0
  return t > f ? t - 1.0f : t;
}
#if defined(__AVX512F__)
template <>
inline F16 Floor(F16 f) {
  // (The all-lanes masked form: GCC 12 warns of an uninitialised source in the plain one.)
  return _mm512_mask_roundscale_ps(f, 0xffff, f, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
}
#endif
#if defined(__AVX__)
template <>
inline F8 Floor(F8 f) {
  return _mm256_floor_ps(f);
}
#endif

// y * 2^t for integer-valued t in [-126, 127] (a power of two built in the exponent bits; exact,
// as long as the product is a normal float): one scale instruction with AVX-512.
template <class V>
inline V ScaleByPowerOfTwo(V y, V t) {
  using I = MaskOf<V>;
  const I e = (__builtin_convertvector(t, I) + 127) << 23;
  V scale;
  std::memcpy(&scale, &e, sizeof(scale));
  return y * scale;
}
#if defined(__AVX512F__)
template <>
inline F16 ScaleByPowerOfTwo(F16 y, F16 t) {
  return _mm512_mask_scalef_ps(y, 0xffff, y, t);
}
#endif
#if defined(__AVX512F__) && defined(__AVX512VL__)
template <>
inline F8 ScaleByPowerOfTwo(F8 y, F8 t) {
  return _mm256_mask_scalef_ps(y, 0xff, y, t);
}
#endif

// exp(x) for x in [-88, 0], lane by lane (Cephes' expf: range reduction by ln 2 and a degree-6
// polynomial; relative error about 1e-7). Callers clamp the argument. The same bits at every
// width and instruction set: Floor and ScaleByPowerOfTwo are exact.
template <class V>
inline V Exp(V x) {
  const V f = x * 1.44269504088896341f + 0.5f;
  const V t = Floor(f);
  V r = x - t * 0.693359375f;
  r = r + t * 2.12194440e-4f;
  const V z = r * r;
  V y = Splat<V>(1.9875691500e-4f);
  y = y * r + 1.3981999507e-3f;
  y = y * r + 8.3334519073e-3f;
  y = y * r + 4.1665795894e-2f;
  y = y * r + 1.6666665459e-1f;
  y = y * r + 5.0000001201e-1f;
  y = y * z + r + 1.0f;
  return ScaleByPowerOfTwo(y, t);
}

}  // namespace mgsr::simd
