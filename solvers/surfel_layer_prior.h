// The surfel layer prior ("surfel_layer"): overlapping 2DGS disks that face the same way should lie
// on one sheet, not stack into a layer a pixel thick whose near side a view renders (a slot's walls
// then stand inside the slot: docs/geometry.md, "A layer of disks").
//
// For each disk i and each of its k nearest disks j (centres c, unit normals n, i's largest scale
// s_i), the neighbour's distance from the pair's mean plane, in units of s_i:
//
//   d_ij = m_ij . (c_j - c_i) / s_i,   m_ij = (n_i + sigma_ij n_j) / 2,  sigma_ij = sign(n_i . n_j)
//   E = 1/N sum_i sum_j g_ij rho(d_ij),   rho(d) = d^2 / (d^2 + tau^2)   (Geman-McClure)
//
// On a sphere every pair's chord is perpendicular to the mean of its two normals, so d_ij = 0: the
// prior does not flatten a curved sheet (the distance from the disk's own plane would). The robust
// penalty lets a true edge or a thin part (two sheets a disk apart) cost a bounded amount. The pair
// weight g_ij = opacity_j * agreement(|n_i . n_j|) * exp(-|c_j - c_i|^2 / (2 s_i^2)) counts only
// pairs that overlap and face the same way (agreement ramps from 0 at cos min_cos to 1 at cos 1);
// the weights, s_i and the neighbour lists are constants of the step (found afresh each step).
//
// Config: "neighbours" (k, 1..16, default 8), "tau" (default 0.5), "min_cos" (0..1, default 0.9),
// "cell_scales" (the search grid's cell in median disk scales, default 3; neighbours are searched
// in the 27 cells around a disk's).
#pragma once

#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <vector>

#include "solvers/primitive_prior.h"

namespace mgsr {

struct SurfelLayerOptions {
  int neighbours = 8;
  double tau = 0.5;
  double min_cos = 0.9;
  double cell_scales = 3;
  static Status FromJson(const nlohmann::json& config, SurfelLayerOptions* out);
};

// One pair's term g * rho(d) and, with the gradient arrays, its derivatives with respect to the
// two centres and the two unit normals (added). Double precision throughout (the gradient test's
// reference).
double SurfelPairEnergy(const double ci[3], const double ni[3], const double cj[3],
                        const double nj[3], double inv_scale, double weight, double tau,
                        double dci[3], double dni[3], double dcj[3], double dnj[3]);

class SurfelLayerPrior : public PrimitivePrior {
 public:
  explicit SurfelLayerPrior(const SurfelLayerOptions& options) : options_(options) {}
  Status Check(const std::vector<ParamBlock>& params) const override;
  double Evaluate(const std::vector<ParamBlock>& params, double scale,
                  const std::vector<ParamBlock>* gradients) override;

  // For tests. The neighbour lists of the last Evaluate: disk i's are Neighbours(i)[0..k) (-1
  // ends a short list), nearest first.
  const int* Neighbours(size_t i) const { return &neighbours_[i * options_.neighbours]; }
  // The energy at `params` (same size as the last Evaluate's) with the last Evaluate's pairs,
  // weights and scales: the function whose gradient Evaluate returns.
  double EnergyAtFixedPairs(const std::vector<ParamBlock>& params);

 private:
  // Centres, unit normals, scales and opacities of the disks.
  void Prepare(const std::vector<ParamBlock>& params);
  // Each disk's k nearest, and the pairs' weights (constants of the step).
  void FindNeighbours();
  void WeighPairs();
  // The energy of the current pairs; with `grad`, its derivatives into d_centres_, d_normals_.
  double Energy(bool grad);

  SurfelLayerOptions options_;
  size_t n_ = 0;
  // Scratch, grown only: per disk centre (3), normal (3), 1 / largest scale, opacity.
  std::vector<double> centres_, normals_, inv_scales_, opacities_;
  std::vector<double> scale_scratch_;
  std::vector<int64_t> cell_coordinates_;        // n_ x 3
  std::vector<std::pair<uint64_t, int>> cells_;  // (cell key, disk), sorted
  std::vector<std::pair<uint64_t, int>> cells_scratch_;
  std::vector<size_t> radix_counts_;
  std::vector<uint64_t> sorted_keys_;          // cells_' keys
  std::vector<double> sorted_centres_;         // the centres in cells_' order
  std::vector<int> neighbours_;                // n_ x k, -1 where fewer were found
  std::vector<double> neighbour_dist2_;        // n_ x k
  std::vector<double> pair_weights_;           // n_ x k, 0 for pairs that do not count
  std::vector<double> pair_inv_scales_;        // n_ x 1: 1 / s_i of the step
  std::vector<double> d_centres_, d_normals_;  // per disk gradient, before the quaternion
};

// Registers the prior as "surfel_layer" (solvers/builtin_priors.cc calls it).
void RegisterSurfelLayerPrior(PriorRegistry* registry);

}  // namespace mgsr
