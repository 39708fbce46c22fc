// Real spherical harmonics up to degree 3, as the 3DGS family evaluates colour from a view
// direction: colour = sum_k Y_k(dir) sh_k + 0.5, clamped at 0 per channel (the clamp mask is kept,
// so the backward gives clamped channels no gradient).
#pragma once

#include <cstddef>
#include <cstdint>

namespace mgsr {

constexpr int kMaxShCoeffs = 16;

// Basis values Y_k(dir) for k < (degree + 1)^2; dir = (x, y, z) must be unit length. (By value:
// the projections call it with a direction they have just stored, and a pointer let the compiler
// read y and z in one 8-byte load, which the processor cannot forward from two 4-byte stores: the
// load waited for the stores to reach the cache, the largest cost of the SH basis in `perf`.)
void ShBasis(int degree, float x, float y, float z, float basis[kMaxShCoeffs]);
inline void ShBasis(int degree, const float dir[3], float basis[kMaxShCoeffs]) {
  ShBasis(degree, dir[0], dir[1], dir[2], basis);
}

// The same and d Y_k / d dir (row k holds the 3 partial derivatives).
void ShBasisWithGradient(int degree, const float dir[3], float basis[kMaxShCoeffs],
                         float dbasis[kMaxShCoeffs][3]);

// Colour from coefficients laid out [k][rgb] (stride 3, `coeffs` has at least (degree+1)^2 rows).
// clamped[c] is set to 1 where the channel was clamped at 0.
void EvalShColor(int degree, const float* coeffs, const float dir[3], float rgb[3],
                 uint8_t clamped[3]);

// The same from basis values computed once (ShBasis) for `n` = (degree + 1)^2 coefficients
// (1, 4, 9 or 16; the FromBasis functions are compiled for these counts): a primitive with two
// colour sets (transmitted and reflected) shares one basis.
void EvalShColorFromBasis(int n, const float basis[kMaxShCoeffs], const float* coeffs, float rgb[3],
                          uint8_t clamped[3]);

// Backward of EvalShColor: adds d/d coeffs into d_coeffs (same layout) and returns d/d dir
// (of the unit direction; chain through the normalisation is the caller's, see NormalizeBackward).
void EvalShColorBackward(int degree, const float* coeffs, const float dir[3],
                         const uint8_t clamped[3], const float d_rgb[3], float* d_coeffs,
                         float d_dir[3]);

// The same from a basis and its gradient computed once (ShBasisWithGradient); *adds* d/d dir
// into `d_dir`.
void EvalShColorBackwardFromBasis(int n, const float basis[kMaxShCoeffs],
                                  const float dbasis[kMaxShCoeffs][3], const float* coeffs,
                                  const uint8_t clamped[3], const float d_rgb[3], float* d_coeffs,
                                  float d_dir[3]);

// The same, but *writes* d/d coeffs: rows k < n get 0 + their gradient (the bits the adding form
// gives on a zeroed row), rows from n on are left alone. The backward passes write the SH blocks'
// gradients whole instead of zeroing them first and adding (10 MB per 3DGS step: two passes over
// memory saved).
void WriteShColorBackwardFromBasis(int n, const float basis[kMaxShCoeffs],
                                   const float dbasis[kMaxShCoeffs][3], const float* coeffs,
                                   const uint8_t clamped[3], const float d_rgb[3], float* d_coeffs,
                                   float d_dir[3]);
// WriteShColorBackwardFromBasis into a primitive's whole gradient row of `row_floats` floats: the
// coefficients above the current degree (from 3 n on) get zero.
void WriteShRowBackward(int n, const float basis[kMaxShCoeffs], const float dbasis[kMaxShCoeffs][3],
                        const float* coeffs, const uint8_t clamped[3], const float d_rgb[3],
                        size_t row_floats, float* d_row, float d_dir[3]);

// dir = v / |v|: given d/d dir, returns d/d v.
void NormalizeBackward(const float v[3], const float d_dir[3], float d_v[3]);

}  // namespace mgsr
