// The vector helpers' tests again, compiled for the compiler's baseline instruction set rather than
// the host's. Without AVX-512 a 16-lane vector is a pair of 8-lane halves with operators of its own
// (simd16.h); an AVX-512 machine's rasterizers never use it, so without this file its tests would
// run only on machines without AVX-512.
#define MGSR_SIMD16_SUITE Simd16Portable
#include "render/simd16_test.cc"
