#include "solvers/surfel_layer_prior.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "mgsr/core/profiler.h"

namespace mgsr {
namespace {

// Grid cell coordinates are clamped to +-2^20 cells around the origin (a disk farther out shares a
// border cell: its candidates are then farther, its distances still exact).
constexpr int64_t kCellLimit = int64_t{1} << 20;

int64_t CellCoordinate(double x, double inv_cell) {
  const double c = std::floor(x * inv_cell);
  if (!(c > -static_cast<double>(kCellLimit))) return -kCellLimit;
  if (!(c < static_cast<double>(kCellLimit))) return kCellLimit;
  return static_cast<int64_t>(c);
}

// Stable LSD radix sort of (key, disk) pairs by key, 16 bits a pass, as many passes as `max_key`
// has digits: pairs that start in disk order end sorted by (key, disk).
void RadixSortByKey(uint64_t max_key, std::vector<std::pair<uint64_t, int>>* pairs,
                    std::vector<std::pair<uint64_t, int>>* scratch, std::vector<size_t>* counts) {
  constexpr int kDigitBits = 16;
  constexpr size_t kDigits = size_t{1} << kDigitBits;
  scratch->resize(pairs->size());
  counts->resize(kDigits);
  for (int shift = 0; shift < 64 && (max_key >> shift) != 0; shift += kDigitBits) {
    std::fill(counts->begin(), counts->end(), 0);
    for (const auto& e : *pairs) ++(*counts)[(e.first >> shift) & (kDigits - 1)];
    size_t total = 0;
    for (size_t& c : *counts) {
      const size_t here = c;
      c = total;
      total += here;
    }
    for (const auto& e : *pairs) (*scratch)[(*counts)[(e.first >> shift) & (kDigits - 1)]++] = e;
    pairs->swap(*scratch);
  }
}

// The disk's normal, the rotation's third column, of the normalised quaternion (w, x, y, z).
void QuaternionNormal(const float q_raw[4], double n[3]) {
  double q[4] = {q_raw[0], q_raw[1], q_raw[2], q_raw[3]};
  const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(len > 0)) {
    n[0] = n[1] = 0;
    n[2] = 1;
    return;
  }
  for (double& v : q) v /= len;
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  n[0] = 2 * (x * z + w * y);
  n[1] = 2 * (y * z - w * x);
  n[2] = 1 - 2 * (x * x + y * y);
}

// d E / d q_raw from d E / d n, through the normalisation.
void QuaternionNormalBackward(const float q_raw[4], const double dn[3], double dq[4]) {
  double q[4] = {q_raw[0], q_raw[1], q_raw[2], q_raw[3]};
  const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(len > 0)) {
    dq[0] = dq[1] = dq[2] = dq[3] = 0;
    return;
  }
  for (double& v : q) v /= len;
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  // Rows: d n_k / d (w, x, y, z) at the unit quaternion.
  const double du[4] = {2 * (y * dn[0] - x * dn[1]), 2 * (z * dn[0] - w * dn[1]) - 4 * x * dn[2],
                        2 * (w * dn[0] + z * dn[1]) - 4 * y * dn[2], 2 * (x * dn[0] + y * dn[1])};
  const double dot = w * du[0] + x * du[1] + y * du[2] + z * du[3];
  for (int k = 0; k < 4; ++k) dq[k] = (du[k] - q[k] * dot) / len;
}

Status ReadNumber(const nlohmann::json& config, const char* key, double lo, double hi,
                  double* out) {
  if (!config.contains(key)) return Status::Ok();
  const nlohmann::json& v = config[key];
  if (!v.is_number() || !(v.get<double>() >= lo) || !(v.get<double>() <= hi))
    return Status::Error(std::string("\"") + key + "\" must be a number in [" + std::to_string(lo) +
                         ", " + std::to_string(hi) + "]");
  *out = v.get<double>();
  return Status::Ok();
}

}  // namespace

Status SurfelLayerOptions::FromJson(const nlohmann::json& config, SurfelLayerOptions* out) {
  SurfelLayerOptions o;
  if (config.is_null()) {
    *out = o;
    return Status::Ok();
  }
  if (!config.is_object()) return Status::Error("config must be an object");
  for (const auto& [key, value] : config.items()) {
    if (key != "neighbours" && key != "tau" && key != "min_cos" && key != "cell_scales")
      return Status::Error("unknown config key \"" + key +
                           "\" (known: neighbours, tau, min_cos, cell_scales)");
  }
  if (config.contains("neighbours")) {
    const nlohmann::json& v = config["neighbours"];
    if (!v.is_number_integer() || v.get<int>() < 1 || v.get<int>() > 16)
      return Status::Error("\"neighbours\" must be an integer in [1, 16]");
    o.neighbours = v.get<int>();
  }
  MGSR_RETURN_IF_ERROR(ReadNumber(config, "tau", 1e-6, 1e6, &o.tau));
  MGSR_RETURN_IF_ERROR(ReadNumber(config, "min_cos", 0, 0.999, &o.min_cos));
  MGSR_RETURN_IF_ERROR(ReadNumber(config, "cell_scales", 0.1, 100, &o.cell_scales));
  *out = o;
  return Status::Ok();
}

double SurfelPairEnergy(const double ci[3], const double ni[3], const double cj[3],
                        const double nj[3], double inv_scale, double weight, double tau,
                        double dci[3], double dni[3], double dcj[3], double dnj[3]) {
  const double cos = ni[0] * nj[0] + ni[1] * nj[1] + ni[2] * nj[2];
  const double sigma = cos < 0 ? -1.0 : 1.0;
  double m[3], delta[3];
  for (int k = 0; k < 3; ++k) {
    m[k] = 0.5 * (ni[k] + sigma * nj[k]);
    delta[k] = cj[k] - ci[k];
  }
  const double d = (m[0] * delta[0] + m[1] * delta[1] + m[2] * delta[2]) * inv_scale;
  const double t2 = tau * tau, den = d * d + t2;
  const double energy = weight * d * d / den;
  if (dci != nullptr) {
    const double de_dd = weight * 2 * d * t2 / (den * den);
    for (int k = 0; k < 3; ++k) {
      const double dc = de_dd * m[k] * inv_scale;  // d E / d c_j
      const double dn = de_dd * 0.5 * delta[k] * inv_scale;
      dcj[k] += dc;
      dci[k] -= dc;
      dni[k] += dn;
      dnj[k] += sigma * dn;
    }
  }
  return energy;
}

Status SurfelLayerPrior::Check(const std::vector<ParamBlock>& params) const {
  // A 2DGS model: two in-plane scales (a 3DGS model's three make it no disk).
  MGSR_RETURN_IF_ERROR(CheckParamBlock(params, "means", 3));
  MGSR_RETURN_IF_ERROR(CheckParamBlock(params, "log_scales", 2));
  MGSR_RETURN_IF_ERROR(CheckParamBlock(params, "quats", 4));
  return CheckParamBlock(params, "opacity_logits", 1);
}

void SurfelLayerPrior::Prepare(const std::vector<ParamBlock>& params) {
  const std::vector<float>& means = *FindParamBlock(params, "means")->data;
  const std::vector<float>& log_scales = *FindParamBlock(params, "log_scales")->data;
  const std::vector<float>& quats = *FindParamBlock(params, "quats")->data;
  const std::vector<float>& opacities = *FindParamBlock(params, "opacity_logits")->data;
  n_ = opacities.size();
  centres_.resize(3 * n_);
  normals_.resize(3 * n_);
  inv_scales_.resize(n_);
  opacities_.resize(n_);
  scale_scratch_.resize(n_);
  const int64_t n = static_cast<int64_t>(n_);
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) centres_[3 * i + k] = means[3 * i + k];
    QuaternionNormal(&quats[4 * i], &normals_[3 * i]);
    const double scale =
        std::exp(static_cast<double>(std::max(log_scales[2 * i], log_scales[2 * i + 1])));
    inv_scales_[i] = scale > 0 ? 1.0 / scale : 0.0;
    scale_scratch_[i] = scale;
    opacities_[i] = 1.0 / (1.0 + std::exp(-static_cast<double>(opacities[i])));
  }
}

void SurfelLayerPrior::FindNeighbours() {
  const int k = options_.neighbours;
  neighbours_.assign(n_ * k, -1);
  neighbour_dist2_.assign(n_ * k, std::numeric_limits<double>::infinity());
  if (n_ < 2) return;
  std::nth_element(scale_scratch_.begin(), scale_scratch_.begin() + n_ / 2, scale_scratch_.end());
  const double cell = options_.cell_scales * scale_scratch_[n_ / 2];
  if (!(cell > 0) || !std::isfinite(cell)) return;
  const double inv_cell = 1.0 / cell;
  // Cells numbered x fastest, then y, then z, over the disks' bounding box grown by one cell on
  // every side (so the cells around a disk exist and their numbers do not wrap).
  cell_coordinates_.resize(3 * n_);
  int64_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = kCellLimit;
    hi[a] = -kCellLimit;
  }
  for (size_t i = 0; i < n_; ++i) {
    for (int a = 0; a < 3; ++a) {
      const int64_t c = CellCoordinate(centres_[3 * i + a], inv_cell);
      cell_coordinates_[3 * i + a] = c;
      lo[a] = std::min(lo[a], c);
      hi[a] = std::max(hi[a], c);
    }
  }
  const uint64_t nx = static_cast<uint64_t>(hi[0] - lo[0] + 3),
                 ny = static_cast<uint64_t>(hi[1] - lo[1] + 3);
  const uint64_t nz = static_cast<uint64_t>(hi[2] - lo[2] + 3);
  cells_.resize(n_);
  for (size_t i = 0; i < n_; ++i) {
    const int64_t* c = &cell_coordinates_[3 * i];
    const uint64_t x = static_cast<uint64_t>(c[0] - lo[0] + 1),
                   y = static_cast<uint64_t>(c[1] - lo[1] + 1),
                   z = static_cast<uint64_t>(c[2] - lo[2] + 1);
    cells_[i] = {(z * ny + y) * nx + x, static_cast<int>(i)};
  }
  RadixSortByKey(nx * ny * nz - 1, &cells_, &cells_scratch_, &radix_counts_);
  // The keys and centres in cell order, contiguous: a disk's candidates are a few runs of these,
  // and disks visited in cell order share them (the search is bound by memory, not arithmetic).
  sorted_keys_.resize(n_);
  sorted_centres_.resize(3 * n_);
  for (size_t p = 0; p < n_; ++p) {
    sorted_keys_[p] = cells_[p].first;
    for (int c = 0; c < 3; ++c) sorted_centres_[3 * p + c] = centres_[3 * cells_[p].second + c];
  }
  // The disks in cell order, in one contiguous part per thread. The 9 runs of 3 cells around a
  // disk start at its key + (-1 + dy nx + dz nx ny) (the cell x - 1, y + dy, z + dz), which grows
  // with the key: each run's start is a cursor that only moves forward, found by one binary
  // search at the part's first disk.
  //
  // Runs are read own row first, then the four rows that share a face with it, then the four
  // corner rows; once a disk has k candidates, a row whose nearest point lies farther than the
  // k-th is skipped (nothing in it could enter the list, so the lists are those of reading every
  // row). Most of the 27 cells lie beyond a disk's k nearest.
  const int64_t n = static_cast<int64_t>(n_);
  static constexpr int kRunOrder[9] = {4, 1, 3, 5, 7, 0, 2, 6, 8};
#pragma omp parallel
  {
    const int64_t threads = omp_get_num_threads(), thread = omp_get_thread_num();
    const int64_t begin = n * thread / threads, end = n * (thread + 1) / threads;
    int64_t cursor[9];
    uint64_t cursor_key = 0;
    for (int64_t p = begin; p < end; ++p) {
      const int i = cells_[p].second;
      const double* c = &sorted_centres_[3 * p];
      const uint64_t key = sorted_keys_[p];
      int run = 0;
      for (int64_t dz = -1; dz <= 1; ++dz) {
        for (int64_t dy = -1; dy <= 1; ++dy, ++run) {
          const uint64_t first_key =
              key - 1 + static_cast<uint64_t>(dy) * nx + static_cast<uint64_t>(dz) * nx * ny;
          if (p == begin) {
            cursor[run] = std::lower_bound(sorted_keys_.begin(), sorted_keys_.end(), first_key) -
                          sorted_keys_.begin();
          } else if (key != cursor_key) {
            while (cursor[run] < n && sorted_keys_[cursor[run]] < first_key) ++cursor[run];
          }
        }
      }
      cursor_key = key;
      int* best = &neighbours_[static_cast<size_t>(i) * k];
      double* best_d2 = &neighbour_dist2_[static_cast<size_t>(i) * k];
      // The distance from the centre to the rows below and above its own in y and in z (0 in a
      // border cell, whose extent the clamp changed); shortened by a rounding margin, so a row
      // is skipped only when it is surely too far.
      double gap[2][2] = {{0, 0}, {0, 0}};
      for (int a = 1; a < 3; ++a) {
        const int64_t cc = cell_coordinates_[3 * static_cast<size_t>(i) + a];
        if (cc <= -kCellLimit || cc >= kCellLimit) continue;
        const double x = c[a], margin = 1e-9 * (std::abs(x) + cell);
        gap[a - 1][0] = std::max(0.0, x - static_cast<double>(cc) * cell - margin);
        gap[a - 1][1] = std::max(0.0, static_cast<double>(cc + 1) * cell - x - margin);
      }
      for (const int run_index : kRunOrder) {
        const int64_t dz = run_index / 3 - 1, dy = run_index % 3 - 1;
        if (best[k - 1] >= 0) {
          const double gy = dy == 0 ? 0.0 : gap[0][dy > 0];
          const double gz = dz == 0 ? 0.0 : gap[1][dz > 0];
          if (gy * gy + gz * gz > best_d2[k - 1]) continue;
        }
        const uint64_t last_key =
            key + 1 + static_cast<uint64_t>(dy) * nx + static_cast<uint64_t>(dz) * nx * ny;
        for (int64_t q = cursor[run_index]; q < n && sorted_keys_[q] <= last_key; ++q) {
          if (q == p) continue;
          const double* cj = &sorted_centres_[3 * q];
          const double d2 = (cj[0] - c[0]) * (cj[0] - c[0]) + (cj[1] - c[1]) * (cj[1] - c[1]) +
                            (cj[2] - c[2]) * (cj[2] - c[2]);
          // Most candidates end here, before their index is read.
          if (d2 > best_d2[k - 1]) continue;
          const int j = cells_[q].second;
          // Ties go to the lower index, so the lists do not depend on the visiting order.
          if (d2 == best_d2[k - 1] && j > best[k - 1] && best[k - 1] >= 0) continue;
          int slot = k - 1;
          while (slot > 0 &&
                 (best_d2[slot - 1] > d2 || (best_d2[slot - 1] == d2 && best[slot - 1] > j))) {
            best_d2[slot] = best_d2[slot - 1];
            best[slot] = best[slot - 1];
            --slot;
          }
          best_d2[slot] = d2;
          best[slot] = j;
        }
      }
    }
  }
}

void SurfelLayerPrior::WeighPairs() {
  const int k = options_.neighbours;
  const double ramp = 1.0 / (1.0 - options_.min_cos);
  pair_weights_.assign(n_ * k, 0.0);
  pair_inv_scales_.assign(inv_scales_.begin(), inv_scales_.begin() + n_);
  const int64_t n = static_cast<int64_t>(n_);
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < n; ++i) {
    const double* ni = &normals_[3 * i];
    const double inv_s = inv_scales_[i];
    for (int slot = 0; slot < k; ++slot) {
      const int j = neighbours_[i * k + slot];
      if (j < 0) break;
      const double* nj = &normals_[3 * j];
      const double agreement = std::min(
          1.0, (std::abs(ni[0] * nj[0] + ni[1] * nj[1] + ni[2] * nj[2]) - options_.min_cos) * ramp);
      if (!(agreement > 0)) continue;
      const double overlap = std::exp(-0.5 * neighbour_dist2_[i * k + slot] * inv_s * inv_s);
      const double weight = opacities_[j] * agreement * overlap;
      if (weight > 0) pair_weights_[i * k + slot] = weight;
    }
  }
}

double SurfelLayerPrior::Energy(bool grad) {
  if (grad) {
    d_centres_.assign(3 * n_, 0.0);
    d_normals_.assign(3 * n_, 0.0);
  }
  const int k = options_.neighbours;
  double energy = 0;
  for (size_t i = 0; i < n_; ++i) {
    const double* ci = &centres_[3 * i];
    const double* ni = &normals_[3 * i];
    for (int slot = 0; slot < k; ++slot) {
      const double weight = pair_weights_[i * k + slot];
      if (weight == 0) continue;
      const int j = neighbours_[i * k + slot];
      const double* cj = &centres_[3 * j];
      const double* nj = &normals_[3 * j];
      energy += grad ? SurfelPairEnergy(ci, ni, cj, nj, pair_inv_scales_[i], weight, options_.tau,
                                        &d_centres_[3 * i], &d_normals_[3 * i], &d_centres_[3 * j],
                                        &d_normals_[3 * j])
                     : SurfelPairEnergy(ci, ni, cj, nj, pair_inv_scales_[i], weight, options_.tau,
                                        nullptr, nullptr, nullptr, nullptr);
    }
  }
  return n_ > 0 ? energy / static_cast<double>(n_) : 0.0;
}

double SurfelLayerPrior::Evaluate(const std::vector<ParamBlock>& params, double scale,
                                  const std::vector<ParamBlock>* gradients) {
  ProfileScope profile("surfel layer prior");
  Prepare(params);
  FindNeighbours();
  WeighPairs();
  const bool grad = gradients != nullptr;
  const double energy = Energy(grad);
  const ParamBlock* means_block = grad ? FindParamBlock(*gradients, "means") : nullptr;
  const ParamBlock* quats_block = grad ? FindParamBlock(*gradients, "quats") : nullptr;
  if (means_block != nullptr && quats_block != nullptr && means_block->data->size() == 3 * n_ &&
      quats_block->data->size() == 4 * n_) {
    std::vector<float>& d_means = *means_block->data;
    std::vector<float>& d_quats = *quats_block->data;
    const std::vector<float>& quats = *FindParamBlock(params, "quats")->data;
    const double f = scale / static_cast<double>(n_);
    const int64_t n = static_cast<int64_t>(n_);
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c)
        d_means[3 * i + c] += static_cast<float>(f * d_centres_[3 * i + c]);
      double dq[4];
      QuaternionNormalBackward(&quats[4 * i], &d_normals_[3 * i], dq);
      for (int c = 0; c < 4; ++c) d_quats[4 * i + c] += static_cast<float>(f * dq[c]);
    }
  }
  return energy;
}

double SurfelLayerPrior::EnergyAtFixedPairs(const std::vector<ParamBlock>& params) {
  const size_t n = n_;
  Prepare(params);
  if (n_ != n) return std::numeric_limits<double>::quiet_NaN();
  return Energy(false);
}

void RegisterSurfelLayerPrior(PriorRegistry* registry) {
  registry->Register(
      "surfel_layer",
      [](const nlohmann::json& config, Status* s) -> std::unique_ptr<PrimitivePrior> {
        SurfelLayerOptions o;
        *s = SurfelLayerOptions::FromJson(config, &o);
        if (!s->ok()) return nullptr;
        return std::make_unique<SurfelLayerPrior>(o);
      });
}

}  // namespace mgsr
