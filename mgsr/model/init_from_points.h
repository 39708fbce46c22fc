// Initialising both branches from points (reference 1.9): one primitive per point, colour from
// the point (SH DC, higher bands 0), opacity 0.1, isotropic scale sqrt(mean squared distance to the
// 3 nearest neighbours). 3DGS: identity rotation, reflected SH DC = transmitted DC, reflected
// opacity 0.1 and beta 0.1 (the reference stores beta = 1 with an infinite logit, frozen until
// its first reset to 0.1; starting at 0.1 is equivalent after that reset). 2DGS: a random but
// seeded rotation.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "mgsr/model/gaussian_model.h"
#include "mgsr/model/surfel_model.h"

namespace mgsr {

constexpr float kShC0 = 0.28209479177387814f;
inline float RgbToShDc(float rgb) { return (rgb - 0.5f) / kShC0; }

// Mean squared distance from each point to its k nearest other points (kd-tree), at least 1e-7.
std::vector<float> MeanSquaredNeighbourDistance(const std::vector<Eigen::Vector3f>& points,
                                                int k = 3);

void InitGaussiansFromPoints(const std::vector<Eigen::Vector3f>& points,
                             const std::vector<Eigen::Vector3f>& colors, int max_sh_degree,
                             GaussianModel* model);
void InitSurfelsFromPoints(const std::vector<Eigen::Vector3f>& points,
                           const std::vector<Eigen::Vector3f>& colors, int max_sh_degree,
                           uint64_t seed, SurfelModel* model);

}  // namespace mgsr
