#include "solvers/surfel_layer_prior.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "mgsr/model/activations.h"
#include "mgsr/model/gaussian_model.h"
#include "mgsr/model/surfel_model.h"

namespace mgsr {
namespace {

// The quaternion (w, x, y, z) that turns +z onto the unit vector n.
void QuaternionOfNormal(const double n[3], float q[4]) {
  // Half-way rotation: q = (1 + z.n, z x n) normalised; -z needs a fixed axis.
  double w = 1 + n[2], x = -n[1], y = n[0], z = 0;
  if (w < 1e-9) {
    w = 0;
    x = 1;
    y = 0;
  }
  const double len = std::sqrt(w * w + x * x + y * y + z * z);
  q[0] = static_cast<float>(w / len);
  q[1] = static_cast<float>(x / len);
  q[2] = static_cast<float>(y / len);
  q[3] = static_cast<float>(z / len);
}

void SetDisk(SurfelModel* m, size_t i, const double c[3], const double n[3], double scale,
             double opacity) {
  for (int k = 0; k < 3; ++k) m->means[3 * i + k] = static_cast<float>(c[k]);
  QuaternionOfNormal(n, &m->quats[4 * i]);
  m->log_scales[2 * i] = m->log_scales[2 * i + 1] = static_cast<float>(std::log(scale));
  m->opacity_logits[i] = InverseSigmoid(static_cast<float>(opacity));
}

// Disks tangent to the unit sphere (Fibonacci points), each as wide as the gap between them.
SurfelModel SphereDisks(size_t n) {
  SurfelModel m;
  m.max_sh_degree = 0;
  m.Resize(n);
  const double golden = M_PI * (3 - std::sqrt(5.0));
  for (size_t i = 0; i < n; ++i) {
    const double z = 1 - 2 * (i + 0.5) / n, r = std::sqrt(1 - z * z), a = golden * i;
    const double c[3] = {r * std::cos(a), r * std::sin(a), z};
    SetDisk(&m, i, c, c, 2.0 / std::sqrt(static_cast<double>(n)), 0.9);
  }
  return m;
}

// A square of disks in the plane z = 0, and as many at z = offset (a layer), each facing +z with
// the normals jittered by `tilt` radians.
SurfelModel TwoSheets(int side, double spacing, double offset, double tilt, uint32_t seed) {
  SurfelModel m;
  m.max_sh_degree = 0;
  m.Resize(2 * side * side);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  size_t i = 0;
  for (int sheet = 0; sheet < 2; ++sheet) {
    for (int a = 0; a < side; ++a) {
      for (int b = 0; b < side; ++b, ++i) {
        const double c[3] = {a * spacing + 0.3 * spacing * u(rng),
                             b * spacing + 0.3 * spacing * u(rng), sheet * offset};
        double n[3] = {tilt * u(rng), tilt * u(rng), 1};
        const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (double& v : n) v /= len;
        SetDisk(&m, i, c, n, spacing, 0.5 + 0.4 * std::abs(u(rng)));
      }
    }
  }
  return m;
}

SurfelModel ZeroLike(const SurfelModel& m) {
  SurfelModel g;
  g.max_sh_degree = m.max_sh_degree;
  g.Resize(m.size());
  return g;
}

// The search reads the 27 cells around a disk's (skipping rows that lie beyond the k-th candidate
// found): each list must be the k nearest, in order, of every disk in those 27 cells (ties to the
// lower index), -1 where there are fewer. Returns how many lists are full and how many reach
// farther than half a cell.
std::pair<int, int> ExpectListsOfTheTwentySevenCells(SurfelModel m) {
  const size_t n = m.size();
  SurfelLayerOptions o;
  SurfelLayerPrior prior(o);
  prior.Evaluate(m.Blocks(), 1.0, nullptr);
  std::vector<double> scales;
  for (size_t i = 0; i < n; ++i)
    scales.push_back(std::exp(static_cast<double>(m.log_scales[2 * i])));
  std::nth_element(scales.begin(), scales.begin() + n / 2, scales.end());
  const double inv_cell = 1.0 / (o.cell_scales * scales[n / 2]);
  auto cell_of = [&](size_t i, int a) {
    return static_cast<int64_t>(std::floor(static_cast<double>(m.means[3 * i + a]) * inv_cell));
  };
  int full = 0, beyond_half_a_cell = 0;
  for (size_t i = 0; i < n; ++i) {
    std::vector<std::pair<double, int>> near;
    for (size_t j = 0; j < n; ++j) {
      bool adjacent = j != i;
      for (int a = 0; a < 3 && adjacent; ++a)
        adjacent = std::abs(cell_of(j, a) - cell_of(i, a)) <= 1;
      if (!adjacent) continue;
      double d2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double d = static_cast<double>(m.means[3 * j + a]) - m.means[3 * i + a];
        d2 += d * d;
      }
      near.push_back({d2, static_cast<int>(j)});
    }
    std::sort(near.begin(), near.end());
    const int* found = prior.Neighbours(i);
    for (int s = 0; s < o.neighbours; ++s) {
      const int expected = s < static_cast<int>(near.size()) ? near[s].second : -1;
      EXPECT_EQ(found[s], expected) << "disk " << i << " slot " << s;
    }
    if (near.size() >= static_cast<size_t>(o.neighbours)) {
      ++full;
      beyond_half_a_cell += near[o.neighbours - 1].first * inv_cell * inv_cell > 0.25;
    }
  }
  return {full, beyond_half_a_cell};
}

TEST(SurfelLayerPriorTest, NeighboursAreTheNearestDisksWithinTheSearchedCells) {
  // Random disks in a box, most of them small, so the grid has many cells.
  SurfelModel m;
  m.max_sh_degree = 0;
  const size_t n = 600;
  m.Resize(n);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  for (size_t i = 0; i < n; ++i) {
    const double c[3] = {u(rng), u(rng), 0.3 * u(rng)}, nz[3] = {0, 0, 1};
    SetDisk(&m, i, c, nz, 0.02 + 0.02 * u(rng), 0.8);
  }
  EXPECT_GT(ExpectListsOfTheTwentySevenCells(m).first, static_cast<int>(n) / 2);  // real lists
}

// Sparse and dense parts, so that lists reach past the disk's own cell and rows are skipped.
TEST(SurfelLayerPriorTest, NeighboursAreTheNearestOfTheTwentySevenCells) {
  SurfelModel m;
  m.max_sh_degree = 0;
  const size_t n = 800;
  m.Resize(n);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  for (size_t i = 0; i < n; ++i) {
    // A quarter spread thinly over a larger box, the rest dense in a corner of it.
    const double spread = i % 4 == 0 ? 2.0 : 0.5;
    const double c[3] = {spread * u(rng), spread * u(rng), 0.5 * spread * u(rng)},
                 nz[3] = {0, 0, 1};
    SetDisk(&m, i, c, nz, 0.02 + 0.03 * u(rng), 0.8);
  }
  EXPECT_GT(ExpectListsOfTheTwentySevenCells(m).second, 20);
}

TEST(SurfelLayerPriorTest, ZeroOnASphereAndPositiveOnALayer) {
  SurfelModel sphere = SphereDisks(800);
  SurfelLayerPrior prior{SurfelLayerOptions()};
  EXPECT_LT(prior.Evaluate(sphere.Blocks(), 1.0, nullptr), 1e-10);
  // The same sheet flat, and then doubled a third of a disk above itself.
  SurfelModel flat = TwoSheets(12, 0.1, 0.0, 0.0, 1);
  EXPECT_LT(prior.Evaluate(flat.Blocks(), 1.0, nullptr), 1e-12);
  SurfelModel layer = TwoSheets(12, 0.1, 0.03, 0.0, 1);
  EXPECT_GT(prior.Evaluate(layer.Blocks(), 1.0, nullptr), 0.05);
}

TEST(SurfelLayerPriorTest, PairGradientMatchesNumericDifferentiation) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 20; ++trial) {
    double x[12];  // ci, ni, cj, nj
    for (double& v : x) v = u(rng);
    if (trial % 2 == 1)
      for (int k = 0; k < 3; ++k) x[9 + k] = -x[3 + k] + 0.1 * u(rng);  // opposed normals
    const double inv_scale = 1.7, weight = 0.6, tau = 0.5;
    double g[12] = {0};
    SurfelPairEnergy(x, x + 3, x + 6, x + 9, inv_scale, weight, tau, g, g + 3, g + 6, g + 9);
    const double h = 1e-6;
    for (int p = 0; p < 12; ++p) {
      double xp[12], xm[12];
      std::copy(x, x + 12, xp);
      std::copy(x, x + 12, xm);
      xp[p] += h;
      xm[p] -= h;
      const double numeric = (SurfelPairEnergy(xp, xp + 3, xp + 6, xp + 9, inv_scale, weight, tau,
                                               nullptr, nullptr, nullptr, nullptr) -
                              SurfelPairEnergy(xm, xm + 3, xm + 6, xm + 9, inv_scale, weight, tau,
                                               nullptr, nullptr, nullptr, nullptr)) /
                             (2 * h);
      EXPECT_NEAR(g[p], numeric, 1e-7 * std::max(1.0, std::abs(numeric)))
          << "trial " << trial << " parameter " << p;
    }
  }
}

TEST(SurfelLayerPriorTest, ParameterGradientMatchesNumericDifferentiation) {
  // Through the quaternion's normalisation to the raw parameters, the pairs and weights held
  // (they are constants of a step).
  SurfelModel m = TwoSheets(5, 0.1, 0.04, 0.2, 5);
  for (size_t i = 0; i < m.size(); ++i)
    for (int k = 0; k < 4; ++k) m.quats[4 * i + k] *= 1.3f;  // not unit: the normalisation counts
  SurfelLayerPrior prior{SurfelLayerOptions()};
  SurfelModel g = ZeroLike(m);
  const std::vector<ParamBlock> gb = g.Blocks();
  const double scale = 2.5;
  const double e = prior.Evaluate(m.Blocks(), scale, &gb);
  ASSERT_GT(e, 0);
  int checked = 0;
  for (const char* block : {"means", "quats"}) {
    std::vector<float>& x = *FindParamBlock(m.Blocks(), block)->data;
    const std::vector<float>& gx = *FindParamBlock(gb, block)->data;
    for (size_t p = 0; p < x.size(); p += 7) {
      const float x0 = x[p], h = 1e-3f;
      x[p] = x0 + h;
      const double ep = prior.EnergyAtFixedPairs(m.Blocks());
      x[p] = x0 - h;
      const double em = prior.EnergyAtFixedPairs(m.Blocks());
      x[p] = x0;
      const double numeric =
          scale * (ep - em) / (static_cast<double>(x0 + h) - static_cast<double>(x0 - h));
      EXPECT_NEAR(gx[p], numeric, 2e-3 * std::max(1.0, std::abs(numeric)))
          << block << " entry " << p;
      ++checked;
    }
  }
  EXPECT_GT(checked, 30);
}

TEST(SurfelLayerPriorTest, DescentThinsALayerAndKeepsASphere) {
  SurfelModel layer = TwoSheets(10, 0.1, 0.04, 0.1, 9);
  SurfelLayerPrior prior{SurfelLayerOptions()};
  const auto spread_z = [](const SurfelModel& m) {
    double mean = 0, var = 0;
    for (size_t i = 0; i < m.size(); ++i) mean += m.means[3 * i + 2];
    mean /= m.size();
    for (size_t i = 0; i < m.size(); ++i) var += std::pow(m.means[3 * i + 2] - mean, 2.0);
    return std::sqrt(var / m.size());
  };
  const double before = spread_z(layer);
  const double e0 = prior.Evaluate(layer.Blocks(), 1.0, nullptr);
  for (int step = 0; step < 200; ++step) {
    SurfelModel g = ZeroLike(layer);
    const std::vector<ParamBlock> gb = g.Blocks();
    prior.Evaluate(layer.Blocks(), 1.0, &gb);
    for (size_t k = 0; k < layer.means.size(); ++k) layer.means[k] -= 0.02f * g.means[k];
    for (size_t k = 0; k < layer.quats.size(); ++k) layer.quats[k] -= 0.02f * g.quats[k];
  }
  EXPECT_LT(spread_z(layer), 0.5 * before);
  EXPECT_LT(prior.Evaluate(layer.Blocks(), 1.0, nullptr), 0.5 * e0);
  // A sphere is a minimum: its gradient is zero.
  SurfelModel sphere = SphereDisks(500);
  SurfelModel g = ZeroLike(sphere);
  const std::vector<ParamBlock> gb = g.Blocks();
  prior.Evaluate(sphere.Blocks(), 1.0, &gb);
  double largest = 0;
  for (float v : g.means) largest = std::max(largest, static_cast<double>(std::abs(v)));
  for (float v : g.quats) largest = std::max(largest, static_cast<double>(std::abs(v)));
  EXPECT_LT(largest, 1e-6);
}

TEST(SurfelLayerPriorTest, ConfigAndModelAreChecked) {
  Status s;
  EXPECT_NE(PriorRegistry::Get().Create("surfel_layer", {{"neighbours", 4}, {"tau", 0.2}}, &s),
            nullptr);
  EXPECT_TRUE(s.ok()) << s.message();
  for (const nlohmann::json& bad :
       {nlohmann::json{{"neighbours", 0}}, nlohmann::json{{"neighbours", 17}},
        nlohmann::json{{"tau", -1}}, nlohmann::json{{"min_cos", 1.5}},
        nlohmann::json{{"radius", 2}}, nlohmann::json(3)}) {
    EXPECT_EQ(PriorRegistry::Get().Create("surfel_layer", bad, &s), nullptr) << bad.dump();
    EXPECT_NE(s.message().find("surfel_layer"), std::string::npos) << s.message();
  }
  EXPECT_EQ(PriorRegistry::Get().Create("no_such_prior", nlohmann::json::object(), &s), nullptr);
  EXPECT_NE(s.message().find("surfel_layer"), std::string::npos) << s.message();  // the known

  SurfelLayerPrior prior{SurfelLayerOptions()};
  SurfelModel surfels = SphereDisks(10);
  EXPECT_TRUE(prior.Check(surfels.Blocks()).ok());
  GaussianModel gaussians;
  gaussians.Resize(10);
  const Status refused = prior.Check(gaussians.Blocks());
  EXPECT_FALSE(refused.ok());
  EXPECT_NE(refused.message().find("log_scales"), std::string::npos) << refused.message();
  // No disks, one disk: nothing to pull.
  SurfelModel none = SphereDisks(0), one = SphereDisks(1);
  EXPECT_EQ(prior.Evaluate(none.Blocks(), 1.0, nullptr), 0.0);
  EXPECT_EQ(prior.Evaluate(one.Blocks(), 1.0, nullptr), 0.0);
}

}  // namespace
}  // namespace mgsr
