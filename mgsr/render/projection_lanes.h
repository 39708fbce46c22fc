// Helpers for the projections' lane loops (ProjectGaussians, ProjectSurfels): they run over blocks
// of kLanes primitives, a scalar pass gathering parameters into the block's lanes, short
// loops over the lanes that GCC vectorises, and a scalar pass writing out. The loops compute what
// the per-primitive Eigen code before them computed, to the bit: the helpers below spell out the
// order of each sum and the fused multiply-adds GCC 12 had chosen for that code on a CPU with FMA
// (read from its assembly, and checked against it on every output), and the plain unfused forms,
// which Eigen's order gives, where the build has no FMA.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "mgsr/core/camera.h"
#include "mgsr/model/activations.h"

namespace mgsr {
namespace projection_lanes {

constexpr int kLanes = 16;

// a b + c with one rounding where the build has FMA instructions (as GCC fused it there).
template <class T>
inline T FusedMultiplyAdd(T a, T b, T c) {
#ifdef __FMA__
  return std::fma(a, b, c);
#else
  return a * b + c;
#endif
}

// *g += d sigmoid'(s) for an activated value s (a logit's gradient), fused as before.
inline void AddSigmoidGradient(float s, float d, float* g) {
  *g = FusedMultiplyAdd(SigmoidGradFromValue(s), d, *g);
}
// d sigmoid'(s) itself: the bits AddSigmoidGradient leaves in a zero.
inline float SigmoidGradient(float s, float d) {
  return FusedMultiplyAdd(SigmoidGradFromValue(s), d, 0.0f);
}

// Three-term dot products. A fixed-size product of row-major floats sums a0 b0 + (a1 b1 + a2 b2),
// which GCC fused as fma(a0, b0, fma(a2, b2, a1 b1)); where it had packed several such sums into
// one vector it fused them the other way round, fma(a0, b0, fma(a1, b1, a2 b2)); a column-major
// double product takes its first two rows as packets, (a0 b0 + a1 b1) + a2 b2, fused from the left
// (its third row as the first form).
template <class T>
inline T DotScalarOrder(T a0, T a1, T a2, T b0, T b1, T b2) {
  return FusedMultiplyAdd(a0, b0, FusedMultiplyAdd(a2, b2, a1 * b1));
}
inline float DotPackedOrder(float a0, float a1, float a2, float b0, float b1, float b2) {
  return FusedMultiplyAdd(a0, b0, FusedMultiplyAdd(a1, b1, a2 * b2));
}
inline double DotPacketOrder(double a0, double a1, double a2, double b0, double b1, double b2) {
  return FusedMultiplyAdd(a2, b2, FusedMultiplyAdd(a1, b1, a0 * b0));
}
// Row r of a column-major 3x3 double product.
inline double DotColumnMajorRow(int r, double a0, double a1, double a2, double b0, double b1,
                                double b2) {
  return r < 2 ? DotPacketOrder(a0, a1, a2, b0, b1, b2) : DotScalarOrder(a0, a1, a2, b0, b1, b2);
}

// std::max by value: GCC vectorises a loop that takes it (its reference to one of two temporaries
// became an index into a stack array that stopped the vectoriser).
inline float MaxValue(float a, float b) { return a < b ? b : a; }

// Eigen's normalized() of lane l's vector (v0, v1, v2) into dir[.][l]: v / |v|, or v where |v|^2
// is 0.
__attribute__((always_inline)) inline void LaneNormalize(float v0, float v1, float v2,
                                                         float (&dir)[3][kLanes], int l) {
  const float sq = DotScalarOrder(v0, v1, v2, v0, v1, v2);
  const float len = std::sqrt(sq);
  const float u0 = v0 / len, u1 = v1 / len, u2 = v2 / len;
  dir[0][l] = sq > 0.0f ? u0 : v0;
  dir[1][l] = sq > 0.0f ? u1 : v1;
  dir[2][l] = sq > 0.0f ? u2 : v2;
}

// 1 / x where x > 0, else 0 (x >= 0 or NaN), with the division taken on every lane and the zero
// masked in: GCC moves a division selected by a condition into a branch, and a branch stops the
// vectoriser. (For x > 0, max(x, the least subnormal) is x.)
inline float ReciprocalOrZero(float x) {
  const float r = 1.0f / MaxValue(x, std::numeric_limits<float>::denorm_min());
  uint32_t bits;
  std::memcpy(&bits, &r, 4);
  bits &= x > 0 ? 0xffffffffu : 0u;
  float out;
  std::memcpy(&out, &bits, 4);
  return out;
}

// QuaternionToRotation (mgsr/model/activations.h) of lane l: the row-major rotation R[.][l] of the
// normalised quaternion (w, x, y, z), the identity for a zero quaternion. (Every quotient is taken,
// then selected: GCC does not if-convert a conditional division.)
__attribute__((always_inline)) inline void LaneRotation(float q0, float q1, float q2, float q3,
                                                        float (&R)[9][kLanes], int l) {
  const float qn = std::sqrt(
      FusedMultiplyAdd(q3, q3, FusedMultiplyAdd(q2, q2, FusedMultiplyAdd(q0, q0, q1 * q1))));
  const bool q_ok = qn > 0;
  const float qd0 = q0 / qn, qd1 = q1 / qn, qd2 = q2 / qn, qd3 = q3 / qn;
  const float w = q_ok ? qd0 : 1.0f, x = q_ok ? qd1 : 0.0f, y = q_ok ? qd2 : 0.0f,
              z = q_ok ? qd3 : 0.0f;
  R[0][l] = FusedMultiplyAdd(-2.0f, FusedMultiplyAdd(y, y, z * z), 1.0f);
  R[1][l] = 2 * FusedMultiplyAdd(x, y, -(w * z));
  R[2][l] = 2 * FusedMultiplyAdd(x, z, w * y);
  R[3][l] = 2 * FusedMultiplyAdd(x, y, w * z);
  R[4][l] = FusedMultiplyAdd(-2.0f, x * x + z * z, 1.0f);
  R[5][l] = 2 * FusedMultiplyAdd(y, z, -(w * x));
  R[6][l] = 2 * FusedMultiplyAdd(x, z, -(w * y));
  R[7][l] = 2 * FusedMultiplyAdd(y, z, w * x);
  R[8][l] = FusedMultiplyAdd(-2.0f, FusedMultiplyAdd(y, y, x * x), 1.0f);
}

// The camera as the lane loops read it, in float.
struct CameraLanes {
  Eigen::Matrix<float, 3, 3, Eigen::RowMajor> Rc;
  Eigen::Vector3f tc, center;
  float fx, fy, cx, cy;
  explicit CameraLanes(const Camera& cam)
      : Rc(cam.R.cast<float>()),
        tc(cam.t.cast<float>()),
        center(cam.Center().cast<float>()),
        fx(static_cast<float>(cam.fx)),
        fy(static_cast<float>(cam.fy)),
        cx(static_cast<float>(cam.cx)),
        cy(static_cast<float>(cam.cy)) {}
};

// NormalizeBackward (mgsr/render/sh.h) of lane l: d_v from d_dir for dir = v / |v|, fused as GCC
// fused it there.
__attribute__((always_inline)) inline void LaneNormalizeBackward(float v0, float v1, float v2,
                                                                 const float (&d_dir)[3][kLanes],
                                                                 int l, float (&d_v)[3][kLanes]) {
  const float len = std::sqrt(FusedMultiplyAdd(v2, v2, FusedMultiplyAdd(v0, v0, v1 * v1)));
  const float inv = ReciprocalOrZero(len);
  const float u0 = v0 * inv, u1 = v1 * inv, u2 = v2 * inv;
  const float dot =
      FusedMultiplyAdd(u2, d_dir[2][l], FusedMultiplyAdd(u0, d_dir[0][l], u1 * d_dir[1][l]));
  d_v[0][l] = FusedMultiplyAdd(-u0, dot, d_dir[0][l]) * inv;
  d_v[1][l] = FusedMultiplyAdd(-u1, dot, d_dir[1][l]) * inv;
  d_v[2][l] = FusedMultiplyAdd(-u2, dot, d_dir[2][l]) * inv;
}

// QuaternionToRotationBackward (mgsr/model/activations.h) of one lane, its sums fused as GCC
// fused them there (each sum from its first term on, the negated first product of du[0] fused).
__attribute__((always_inline)) inline void LaneRotationBackward(float q0, float q1, float q2,
                                                                float q3, const float (&dR)[9],
                                                                float (&dq)[4][kLanes], int l) {
  const float n = std::sqrt(
      FusedMultiplyAdd(q3, q3, FusedMultiplyAdd(q2, q2, FusedMultiplyAdd(q0, q0, q1 * q1))));
  const bool ok = n > 0;
  const float w = q0 / n, x = q1 / n, y = q2 / n, z = q3 / n;
  const float x2 = x + x, y2 = -2.0f * y, z2 = -2.0f * z;  // 2 x, -2 y, -2 z
  float du[4];
  float s = FusedMultiplyAdd(-z, dR[1], y * dR[2]);
  s = FusedMultiplyAdd(z, dR[3], s);
  s = FusedMultiplyAdd(-x, dR[5], s);
  s = FusedMultiplyAdd(-y, dR[6], s);
  du[0] = 2 * FusedMultiplyAdd(x, dR[7], s);
  s = FusedMultiplyAdd(y, dR[1], z * dR[2]);
  s = FusedMultiplyAdd(y, dR[3], s);
  s = FusedMultiplyAdd(-x2, dR[4], s);
  s = FusedMultiplyAdd(-w, dR[5], s);
  s = FusedMultiplyAdd(z, dR[6], s);
  s = FusedMultiplyAdd(w, dR[7], s);
  du[1] = 2 * FusedMultiplyAdd(-x2, dR[8], s);
  s = FusedMultiplyAdd(y2, dR[0], x * dR[1]);
  s = FusedMultiplyAdd(w, dR[2], s);
  s = FusedMultiplyAdd(x, dR[3], s);
  s = FusedMultiplyAdd(z, dR[5], s);
  s = FusedMultiplyAdd(-w, dR[6], s);
  s = FusedMultiplyAdd(z, dR[7], s);
  du[2] = 2 * FusedMultiplyAdd(y2, dR[8], s);
  s = FusedMultiplyAdd(z2, dR[0], -(w * dR[1]));
  s = FusedMultiplyAdd(x, dR[2], s);
  s = FusedMultiplyAdd(w, dR[3], s);
  s = FusedMultiplyAdd(z2, dR[4], s);
  s = FusedMultiplyAdd(y, dR[5], s);
  s = FusedMultiplyAdd(x, dR[6], s);
  du[3] = 2 * FusedMultiplyAdd(y, dR[7], s);
  const float u[4] = {w, x, y, z};
  const float dot =
      FusedMultiplyAdd(z, du[3], FusedMultiplyAdd(y, du[2], FusedMultiplyAdd(w, du[0], x * du[1])));
  for (int k = 0; k < 4; ++k) {
    const float g = FusedMultiplyAdd(-u[k], dot, du[k]) / n;
    dq[k][l] = ok ? g : 0.0f;
  }
}

}  // namespace projection_lanes
}  // namespace mgsr
