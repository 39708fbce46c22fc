// Initialising both branches from points (method.md 1.9): one primitive per point, colour from
// the point (SH DC, higher bands 0), opacity 0.1, isotropic scale sqrt(mean squared distance to the
// 3 nearest neighbours). 3DGS: identity rotation, reflected SH DC = transmitted DC, reflected
// opacity 0.1 and beta 0.1 (the reference stores beta = 1 with an infinite logit, frozen until
// its first reset to 0.1; starting at 0.1 is equivalent after that reset). 2DGS: a random but
// seeded rotation (the reference), or the principal axes of each point's neighbourhood
// (SurfelOrientation::kNeighbourhood).
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
// Rotation per point whose columns are the principal axes of the point and its k - 1 nearest
// neighbours, largest spread first: the third column is the normal of the best-fitting plane (sign
// arbitrary; surfels are two-sided). Right-handed; (w, x, y, z) per point, 4 x N. Fewer than 3
// points: identity.
std::vector<float> NeighbourhoodRotations(const std::vector<Eigen::Vector3f>& points, int k = 16);

// Spreads the points over their own surfaces until there are `target` of them: each point stays
// and gains copies (its colour) uniformly in a disk of half its root-mean-square distance to its 3
// nearest neighbours, in the plane of its k nearest (NeighbourhoodRotations). Copies are shared
// out evenly, so every point has floor or ceil of target / n of them in all. Does nothing when
// target <= n or there are fewer than 3 points. Seeded; the order is each point followed by its
// copies. Why: a disk starts as wide as the gap to its neighbours, and from a sparse cloud that
// is wide enough to span a groove or a slot, which the fit then keeps (docs/geometry.md).
void SpreadPointsOverTheirSurfaces(size_t target, uint64_t seed,
                                   std::vector<Eigen::Vector3f>* points,
                                   std::vector<Eigen::Vector3f>* colors, int k = 16);

enum class SurfelOrientation {
  kRandom,         // the reference: U(0,1)^4, seeded
  kNeighbourhood,  // disk in the plane of the point's 16 nearest neighbours
};

void InitSurfelsFromPoints(const std::vector<Eigen::Vector3f>& points,
                           const std::vector<Eigen::Vector3f>& colors, int max_sh_degree,
                           uint64_t seed, SurfelModel* model,
                           SurfelOrientation orientation = SurfelOrientation::kRandom);

}  // namespace mgsr
