// Helpers for the projections' lane loops (ProjectGaussians, ProjectSurfels): they run over blocks
// of kProjectionLanes primitives, a scalar pass gathering parameters into the block's lanes, short
// loops over the lanes that GCC vectorises, and a scalar pass writing out. The loops compute what
// the per-primitive Eigen code before them computed, to the bit: the helpers below spell out the
// order of each sum and the fused multiply-adds GCC 12 had chosen for that code on a CPU with FMA
// (read from its assembly, and checked against it on every output), and the plain unfused forms,
// which Eigen's order gives, where the build has no FMA.
#pragma once

#include <cmath>

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

// std::max and std::min by value: GCC vectorises a loop that takes them (their reference to one of
// two temporaries became an index into a stack array that stopped the vectoriser).
inline float MaxValue(float a, float b) { return a < b ? b : a; }
inline float MinValue(float a, float b) { return b < a ? b : a; }

// QuaternionToRotation (mgsr/model/activations.h) of lane l: the row-major rotation R[.][l] of the
// normalised quaternion (w, x, y, z), the identity for a zero quaternion. (Every quotient is taken,
// then selected: GCC does not if-convert a conditional division.)
inline void LaneRotation(float q0, float q1, float q2, float q3, float (&R)[9][kLanes], int l) {
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

}  // namespace projection_lanes
}  // namespace mgsr
