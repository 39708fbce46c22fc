// 16-lane float vectors (one 16-pixel tile row) with GCC/Clang vector extensions: the compiler
// maps them onto AVX-512, AVX2 or SSE registers, whichever the build targets. Only what the
// rasterizers need: arithmetic comes from the extension, plus masks, select, min/max, abs, loads
// and a branch-free exp.
#pragma once

#include <cstdint>
#include <cstring>

namespace mgsr::simd {

typedef float F16 __attribute__((vector_size(64)));
typedef int32_t I16 __attribute__((vector_size(64)));  // lane masks: -1 (true) or 0
// Unaligned views for loads and stores.
typedef float F16u __attribute__((vector_size(64), aligned(4)));

inline F16 Load(const float* p) { return *reinterpret_cast<const F16u*>(p); }
inline void Store(float* p, F16 v) { *reinterpret_cast<F16u*>(p) = v; }
inline F16 Splat(float v) { return F16{} + v; }
inline F16 Lanes() { return F16{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15}; }

inline F16 Select(I16 mask, F16 a, F16 b) { return mask ? a : b; }
inline F16 Min(F16 a, F16 b) { return a < b ? a : b; }
inline F16 Max(F16 a, F16 b) { return a > b ? a : b; }
inline F16 Abs(F16 a) { return a < 0.0f ? -a : a; }
inline F16 Masked(I16 mask, F16 a) { return mask ? a : F16{}; }

typedef float F8 __attribute__((vector_size(32)));
typedef float F4 __attribute__((vector_size(16)));
typedef int32_t I8 __attribute__((vector_size(32)));
typedef int32_t I4 __attribute__((vector_size(16)));

// Horizontal reductions by halving (a few shuffles instead of 15 dependent scalar adds).
inline float Sum(F16 v) {
  F8 a, b;
  std::memcpy(&a, &v, sizeof(a));
  std::memcpy(&b, reinterpret_cast<const char*>(&v) + sizeof(a), sizeof(b));
  const F8 s8 = a + b;
  F4 c, d;
  std::memcpy(&c, &s8, sizeof(c));
  std::memcpy(&d, reinterpret_cast<const char*>(&s8) + sizeof(c), sizeof(d));
  const F4 s4 = c + d;
  return (s4[0] + s4[2]) + (s4[1] + s4[3]);
}

inline bool Any(I16 mask) {
  I8 a, b;
  std::memcpy(&a, &mask, sizeof(a));
  std::memcpy(&b, reinterpret_cast<const char*>(&mask) + sizeof(a), sizeof(b));
  const I8 o8 = a | b;
  I4 c, d;
  std::memcpy(&c, &o8, sizeof(c));
  std::memcpy(&d, reinterpret_cast<const char*>(&o8) + sizeof(c), sizeof(d));
  const I4 o4 = c | d;
  return (o4[0] | o4[1] | o4[2] | o4[3]) != 0;
}

// exp(x) for x in [-88, 0], lane by lane (Cephes' expf: range reduction by ln 2 and a degree-6
// polynomial; relative error about 1e-7). Callers clamp the argument.
inline F16 Exp(F16 x) {
  const F16 f = x * 1.44269504088896341f + 0.5f;
  F16 t = __builtin_convertvector(__builtin_convertvector(f, I16), F16);  // truncates toward 0
  t = t > f ? t - 1.0f : t;                                               // floor
  F16 r = x - t * 0.693359375f;
  r = r + t * 2.12194440e-4f;
  const F16 z = r * r;
  F16 y = Splat(1.9875691500e-4f);
  y = y * r + 1.3981999507e-3f;
  y = y * r + 8.3334519073e-3f;
  y = y * r + 4.1665795894e-2f;
  y = y * r + 1.6666665459e-1f;
  y = y * r + 5.0000001201e-1f;
  y = y * z + r + 1.0f;
  const I16 e = (__builtin_convertvector(t, I16) + 127) << 23;
  F16 scale;
  std::memcpy(&scale, &e, sizeof(scale));
  return y * scale;
}

}  // namespace mgsr::simd
