// Float vectors of 16 lanes (one 16-pixel tile row) and 8 lanes (half a row, for primitives whose
// footprint in a tile is at most 8 columns wide) with GCC/Clang vector extensions: the compiler
// maps them onto AVX-512, AVX2 or SSE registers, whichever the build targets. Only what the
// rasterizers need: arithmetic comes from the extension, plus masks, select, min/max, abs, loads
// and a branch-free exp. Every helper is generic over the width, so a pixel loop written once as a
// template runs at either width.
//
// Where the build has no AVX-512, a 16-lane vector is a pair of 8-lane halves (`Twin`) rather than
// a 64-byte extension vector: GCC 12 turns the 64-byte vectors' comparisons, selects and
// conversions into one scalar instruction per lane when no 512-bit registers exist (measured on an
// AVX2 Zen 3: `BM_GaussianForwardBackward` 100k, 256 px, 2 threads took 219 ms against ~32 ms on
// an AVX-512 Zen 4), while every 8-lane operation is one AVX instruction. The pair has the vector
// extension's operators, so the pixel loops read the same at either build; only `cond ? a : b` on
// masks is spelled `IfElse(cond, a, b)`, which works for both.
#pragma once

#include <cstdint>
#include <cstring>
#include <type_traits>

#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace mgsr::simd {

typedef float F8 __attribute__((vector_size(32)));
typedef int32_t I8 __attribute__((vector_size(32)));
typedef uint32_t U8 __attribute__((vector_size(32)));
typedef float F4 __attribute__((vector_size(16)));
typedef int32_t I4 __attribute__((vector_size(16)));

#if defined(__AVX512F__)
#define MGSR_SIMD_NATIVE16 1
typedef float F16 __attribute__((vector_size(64)));
typedef int32_t I16 __attribute__((vector_size(64)));  // lane masks: -1 (true) or 0
typedef uint32_t U16 __attribute__((vector_size(64)));
#else
#define MGSR_SIMD_NATIVE16 0
// 16 lanes as two 8-lane halves, lanes 0-7 in `lo` (the same memory layout as the 64-byte vector).
// H is F8, I8 or U8; comparisons of float halves give I8 halves (lane masks, -1 or 0).
template <class H>
struct Twin {
  using Elem = typename std::remove_reference<decltype(H{}[0])>::type;
  H lo, hi;
  // Lane access through the element type (GCC vector types alias their element type).
  Elem& operator[](int i) { return reinterpret_cast<Elem*>(this)[i]; }
  const Elem& operator[](int i) const { return reinterpret_cast<const Elem*>(this)[i]; }
};
typedef Twin<F8> F16;
typedef Twin<I8> I16;
typedef Twin<U8> U16;

#define MGSR_TWIN_INLINE inline __attribute__((always_inline))
#define MGSR_TWIN_BINARY(op)                                                  \
  template <class H>                                                          \
  MGSR_TWIN_INLINE Twin<H> operator op(Twin<H> a, Twin<H> b) {                \
    return {a.lo op b.lo, a.hi op b.hi};                                      \
  }                                                                           \
  template <class H>                                                          \
  MGSR_TWIN_INLINE Twin<H> operator op(Twin<H> a, typename Twin<H>::Elem b) { \
    return {a.lo op b, a.hi op b};                                            \
  }                                                                           \
  template <class H>                                                          \
  MGSR_TWIN_INLINE Twin<H> operator op(typename Twin<H>::Elem a, Twin<H> b) { \
    return {a op b.lo, a op b.hi};                                            \
  }                                                                           \
  template <class H>                                                          \
  MGSR_TWIN_INLINE Twin<H>& operator op##=(Twin<H>& a, Twin<H> b) {           \
    return a = a op b;                                                        \
  }
MGSR_TWIN_BINARY(+)
MGSR_TWIN_BINARY(-)
MGSR_TWIN_BINARY(*)
MGSR_TWIN_BINARY(/)
MGSR_TWIN_BINARY(&)
MGSR_TWIN_BINARY(|)
MGSR_TWIN_BINARY(^)
#undef MGSR_TWIN_BINARY

#define MGSR_TWIN_COMPARE(op)                                              \
  template <class H>                                                       \
  MGSR_TWIN_INLINE auto operator op(Twin<H> a, Twin<H> b) {                \
    return Twin<decltype(H {} op H{})>{a.lo op b.lo, a.hi op b.hi};        \
  }                                                                        \
  template <class H>                                                       \
  MGSR_TWIN_INLINE auto operator op(Twin<H> a, typename Twin<H>::Elem b) { \
    return Twin<decltype(H {} op H{})>{a.lo op b, a.hi op b};              \
  }                                                                        \
  template <class H>                                                       \
  MGSR_TWIN_INLINE auto operator op(typename Twin<H>::Elem a, Twin<H> b) { \
    return Twin<decltype(H {} op H{})>{a op b.lo, a op b.hi};              \
  }
MGSR_TWIN_COMPARE(<)
MGSR_TWIN_COMPARE(<=)
MGSR_TWIN_COMPARE(>)
MGSR_TWIN_COMPARE(>=)
MGSR_TWIN_COMPARE(==)
MGSR_TWIN_COMPARE(!=)
#undef MGSR_TWIN_COMPARE

template <class H>
MGSR_TWIN_INLINE Twin<H> operator-(Twin<H> a) {
  return {-a.lo, -a.hi};
}
template <class H>
MGSR_TWIN_INLINE Twin<H> operator~(Twin<H> a) {
  return {~a.lo, ~a.hi};
}
template <class H>
MGSR_TWIN_INLINE Twin<H> operator<<(Twin<H> a, int n) {
  return {a.lo << n, a.hi << n};
}
#undef MGSR_TWIN_INLINE
#endif

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
// `cond ? a : b` lane by lane (the vector extension's select; on the 8-lane halves of a pair).
template <class M, class V>
inline V IfElse(M cond, V a, V b) {
  return cond ? a : b;
}
#if !MGSR_SIMD_NATIVE16
inline F16 IfElse(I16 cond, F16 a, F16 b) { return {cond.lo ? a.lo : b.lo, cond.hi ? a.hi : b.hi}; }
#endif

// Stores the lanes of `v` where `mask` is set, leaving the others in memory as they are: one
// masked store where the build targets AVX-512 (no load of the old values), a blend otherwise.
// (The intrinsics take these vector types as they are: same size, same element type.)
inline void StoreMasked(float* p, I16 mask, F16 v) {
#if defined(__AVX512F__)
  _mm512_mask_storeu_ps(p, _mm512_test_epi32_mask((__m512i)mask, (__m512i)mask), v);
#else
  Store(p, IfElse(mask, v, Load<F16>(p)));
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
  return IfElse(mask, a, b);
}
template <class V>
inline V Min(V a, V b) {
  return IfElse(a < b, a, b);
}
template <class V>
inline V Max(V a, V b) {
  return IfElse(a > b, a, b);
}
template <class V>
inline V Abs(V a) {
  return IfElse(a < 0.0f, -a, a);
}
template <class V>
inline V Masked(MaskOf<V> mask, V a) {
  return IfElse(mask, a, V{});
}

// a * b + c and a * b - c with one rounding, wherever they stand: the compiler fuses a multiply
// and an add only as the code around lets it, so where two passes must compute the same value to
// the bit, the fusing is spelled out. (Without FMA instructions: unfused, as the compiler does.)
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
inline F16 Fma(F16 a, F16 b, F16 c) {
#if MGSR_SIMD_NATIVE16
  return _mm512_fmadd_ps(a, b, c);
#else
  return {Fma(a.lo, b.lo, c.lo), Fma(a.hi, b.hi, c.hi)};
#endif
}
inline F16 Fms(F16 a, F16 b, F16 c) {
#if MGSR_SIMD_NATIVE16
  return _mm512_fmsub_ps(a, b, c);
#else
  return {Fms(a.lo, b.lo, c.lo), Fms(a.hi, b.hi, c.hi)};
#endif
}

// Unsigned integers below 2^24 (exact as floats) to floats and back, lane by lane. (AVX2 has no
// unsigned conversions; in this range the signed ones give the same values.)
inline F16 ToFloat(U16 u) {
#if MGSR_SIMD_NATIVE16
  return __builtin_convertvector(u, F16);
#else
  return {__builtin_convertvector((I8)u.lo, F8), __builtin_convertvector((I8)u.hi, F8)};
#endif
}
inline U16 ToUint(F16 v) {
#if MGSR_SIMD_NATIVE16
  return __builtin_convertvector(v, U16);
#else
  return {(U8) __builtin_convertvector(v.lo, I8), (U8) __builtin_convertvector(v.hi, I8)};
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

inline void SumEach(const F8* v, float out[16]) {
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

// The horizontal sums of 16 vectors v[0..15] at once: out[i] = Sum(v[i]) to the bit (every lane is
// added in the pairs Sum uses), but the halving steps of different vectors share their shuffles and
// adds: 16-lane vectors take 15 adds and 30 two-source shuffles for all 16 sums instead of about
// four of each per sum. For the per-primitive gradient sums that close each entry of the
// rasterizers' backward passes.
inline void SumEach(const F16* v, float out[16]) {
#if MGSR_SIMD_NATIVE16
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
#else
  // Sum(F16) adds the halves first, then sums the 8-lane vector: the same additions.
  F8 halves[16];
  for (int i = 0; i < 16; ++i) halves[i] = v[i].lo + v[i].hi;
  SumEach(halves, out);
#endif
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
#if MGSR_SIMD_NATIVE16
  __m512i v;
  std::memcpy(&v, &mask, sizeof(v));
  return _mm512_test_epi32_mask(v, v) != 0;
#else
  return Any(mask.lo | mask.hi);
#endif
}

// floor(f), exact for |f| < 2^31: one rounding instruction where the build has one (AVX / AVX-512),
// else truncation through int32 and a correction for negative non-integers.
template <class V>
inline V Floor(V f) {
  using I = MaskOf<V>;
  V t = __builtin_convertvector(__builtin_convertvector(f, I), V);  // truncates toward 0
  return IfElse(t > f, t - 1.0f, t);
}
#if MGSR_SIMD_NATIVE16
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
#if !MGSR_SIMD_NATIVE16
template <>
inline F16 Floor(F16 f) {
  return {Floor(f.lo), Floor(f.hi)};
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
#if MGSR_SIMD_NATIVE16
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
#if !MGSR_SIMD_NATIVE16
template <>
inline F16 ScaleByPowerOfTwo(F16 y, F16 t) {
  return {ScaleByPowerOfTwo(y.lo, t.lo), ScaleByPowerOfTwo(y.hi, t.hi)};
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
