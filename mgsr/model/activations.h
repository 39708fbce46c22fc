// Parameter activations, in one place: the optimiser sees raw values, the renderers the activated
// ones. scale = exp(log_scale), opacity/beta = sigmoid(logit), rotation = normalise(quaternion).
#pragma once

#include <cmath>

namespace mgsr {

inline float Sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }
// d sigmoid / dx expressed through the activated value s.
inline float SigmoidGradFromValue(float s) { return s * (1.0f - s); }
inline float InverseSigmoid(float y) { return std::log(y / (1.0f - y)); }

// Rotation matrix (row-major 3x3) of the normalised quaternion (w, x, y, z). Returns false (and the
// identity) for a zero quaternion.
inline bool QuaternionToRotation(const float q_raw[4], float R[9], float q_unit[4]) {
  const float n = std::sqrt(q_raw[0] * q_raw[0] + q_raw[1] * q_raw[1] + q_raw[2] * q_raw[2] +
                            q_raw[3] * q_raw[3]);
  if (!(n > 0)) {
    q_unit[0] = 1;
    q_unit[1] = q_unit[2] = q_unit[3] = 0;
  } else {
    for (int k = 0; k < 4; ++k) q_unit[k] = q_raw[k] / n;
  }
  const float w = q_unit[0], x = q_unit[1], y = q_unit[2], z = q_unit[3];
  R[0] = 1 - 2 * (y * y + z * z);
  R[1] = 2 * (x * y - w * z);
  R[2] = 2 * (x * z + w * y);
  R[3] = 2 * (x * y + w * z);
  R[4] = 1 - 2 * (x * x + z * z);
  R[5] = 2 * (y * z - w * x);
  R[6] = 2 * (x * z - w * y);
  R[7] = 2 * (y * z + w * x);
  R[8] = 1 - 2 * (x * x + y * y);
  return n > 0;
}

// Backward of QuaternionToRotation: dL/dR (row-major) -> dL/d q_raw, including the normalisation
// Jacobian (I - u u^T) / |q|.
inline void QuaternionToRotationBackward(const float q_raw[4], const float dR[9], float dq_raw[4]) {
  const float n = std::sqrt(q_raw[0] * q_raw[0] + q_raw[1] * q_raw[1] + q_raw[2] * q_raw[2] +
                            q_raw[3] * q_raw[3]);
  if (!(n > 0)) {
    dq_raw[0] = dq_raw[1] = dq_raw[2] = dq_raw[3] = 0;
    return;
  }
  const float w = q_raw[0] / n, x = q_raw[1] / n, y = q_raw[2] / n, z = q_raw[3] / n;
  // d R_ij / d (w, x, y, z) contracted with dR.
  float du[4];
  du[0] = 2 * (-z * dR[1] + y * dR[2] + z * dR[3] - x * dR[5] - y * dR[6] + x * dR[7]);
  du[1] = 2 * (y * dR[1] + z * dR[2] + y * dR[3] - 2 * x * dR[4] - w * dR[5] + z * dR[6] +
               w * dR[7] - 2 * x * dR[8]);
  du[2] = 2 * (-2 * y * dR[0] + x * dR[1] + w * dR[2] + x * dR[3] + z * dR[5] - w * dR[6] +
               z * dR[7] - 2 * y * dR[8]);
  du[3] = 2 * (-2 * z * dR[0] - w * dR[1] + x * dR[2] + w * dR[3] - 2 * z * dR[4] + y * dR[5] +
               x * dR[6] + y * dR[7]);
  const float u[4] = {w, x, y, z};
  const float dot = u[0] * du[0] + u[1] * du[1] + u[2] * du[2] + u[3] * du[3];
  for (int k = 0; k < 4; ++k) dq_raw[k] = (du[k] - u[k] * dot) / n;
}

}  // namespace mgsr
