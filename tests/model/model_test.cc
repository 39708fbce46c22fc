#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "mgsr/core/rng.h"
#include "mgsr/model/activations.h"
#include "mgsr/model/gaussian_model.h"
#include "mgsr/model/init_from_points.h"
#include "mgsr/model/surfel_model.h"
#include "mgsr/render/raster_scratch.h"

namespace mgsr {
namespace {

std::vector<Eigen::Vector3f> Grid(int n, float spacing) {
  std::vector<Eigen::Vector3f> p;
  for (int x = 0; x < n; ++x) {
    for (int y = 0; y < n; ++y) {
      for (int z = 0; z < n; ++z) p.emplace_back(x * spacing, y * spacing, z * spacing);
    }
  }
  return p;
}

TEST(InitFromPointsTest, NeighbourDistancesOnAGrid) {
  const auto pts = Grid(5, 0.1f);
  const auto d2 = MeanSquaredNeighbourDistance(pts, 3);
  // An interior grid point has 6 neighbours at exactly the spacing.
  const int centre = 2 * 25 + 2 * 5 + 2;
  EXPECT_NEAR(d2[centre], 0.01f, 1e-6f);
  // Duplicates give the floor, not zero.
  const auto dup = MeanSquaredNeighbourDistance({{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}}, 3);
  EXPECT_FLOAT_EQ(dup[0], 1e-7f);
}

TEST(InitFromPointsTest, GaussiansFollowTheReference) {
  const auto pts = Grid(4, 0.2f);
  std::vector<Eigen::Vector3f> colors(pts.size(), Eigen::Vector3f(0.2f, 0.5f, 0.9f));
  GaussianModel m;
  InitGaussiansFromPoints(pts, colors, 3, &m);
  ASSERT_EQ(m.size(), pts.size());
  const int K = m.sh_coeffs();
  for (size_t i = 0; i < m.size(); ++i) {
    EXPECT_NEAR(Sigmoid(m.opacity_logits[i]), 0.1f, 1e-6f);
    EXPECT_NEAR(Sigmoid(m.ref_opacity_logits[i]), 0.1f, 1e-6f);
    EXPECT_NEAR(Sigmoid(m.beta_logits[i]), 0.1f, 1e-6f);
    EXPECT_EQ(m.quats[4 * i], 1.0f);
    // SH DC reproduces the colour: C0 * dc + 0.5.
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(kShC0 * m.sh[i * K * 3 + c] + 0.5f, colors[i][c], 1e-6f);
      EXPECT_EQ(m.ref_sh[i * K * 3 + c], m.sh[i * K * 3 + c]);
    }
    for (int k = 3; k < K * 3; ++k) EXPECT_EQ(m.sh[i * K * 3 + k], 0.0f);
    EXPECT_EQ(m.log_scales[3 * i], m.log_scales[3 * i + 2]);
  }
  // A corner point's 3 nearest neighbours are at the spacing.
  EXPECT_NEAR(std::exp(m.log_scales[0]), 0.2f, 1e-5f);
}

TEST(InitFromPointsTest, SurfelsHaveSeededRandomRotations) {
  const auto pts = Grid(3, 0.1f);
  std::vector<Eigen::Vector3f> colors(pts.size(), Eigen::Vector3f(0.5f, 0.5f, 0.5f));
  SurfelModel a, b, c;
  InitSurfelsFromPoints(pts, colors, 3, 1, &a);
  InitSurfelsFromPoints(pts, colors, 3, 1, &b);
  InitSurfelsFromPoints(pts, colors, 3, 2, &c);
  EXPECT_EQ(a.quats, b.quats);
  EXPECT_NE(a.quats, c.quats);
  EXPECT_EQ(a.log_scales.size(), 2 * pts.size());
  EXPECT_NE(a.quats[0], a.quats[4]);
}

// Points on a tilted plane and on a sphere: every disk lies in the local surface (its third axis
// along the plane's normal / the radius), the rotation is proper, and the option reaches the model.
TEST(InitFromPointsTest, NeighbourhoodOrientationLaysDisksInTheSurface) {
  Rng rng(3);
  const Eigen::Vector3d plane_normal = Eigen::Vector3d(0.3, -0.5, 1.0).normalized();
  const Eigen::Vector3d a = plane_normal.unitOrthogonal(), b = plane_normal.cross(a);
  std::vector<Eigen::Vector3f> plane, sphere;
  for (int i = 0; i < 400; ++i) {
    plane.push_back((rng.Uniform() * a + rng.Uniform() * b + 0.2 * plane_normal).cast<float>());
    Eigen::Vector3d d(rng.Normal(), rng.Normal(), rng.Normal());
    sphere.push_back((0.7 * d.normalized()).cast<float>());
  }
  auto third_axis = [](const std::vector<float>& q, size_t i, double* det) {
    const Eigen::Quaterniond r(q[4 * i], q[4 * i + 1], q[4 * i + 2], q[4 * i + 3]);
    EXPECT_NEAR(r.norm(), 1.0, 1e-5);
    *det = r.normalized().toRotationMatrix().determinant();
    return Eigen::Vector3d(r.normalized().toRotationMatrix().col(2));
  };
  const std::vector<float> qp = NeighbourhoodRotations(plane);
  const std::vector<float> qs = NeighbourhoodRotations(sphere);
  double worst_plane = 1, worst_sphere = 1, det = 0;
  for (size_t i = 0; i < plane.size(); ++i) {
    worst_plane = std::min(worst_plane, std::abs(third_axis(qp, i, &det).dot(plane_normal)));
    EXPECT_NEAR(det, 1.0, 1e-5);
    const Eigen::Vector3d radial = sphere[i].cast<double>().normalized();
    worst_sphere = std::min(worst_sphere, std::abs(third_axis(qs, i, &det).dot(radial)));
  }
  EXPECT_GT(worst_plane, 0.9999);  // exact up to float rounding
  EXPECT_GT(worst_sphere, 0.97);   // 16 neighbours span ~0.2 of the radius: a slight chord tilt
  SurfelModel m, random;
  std::vector<Eigen::Vector3f> colors(sphere.size(), Eigen::Vector3f(0.5f, 0.5f, 0.5f));
  InitSurfelsFromPoints(sphere, colors, 3, 1, &m, SurfelOrientation::kNeighbourhood);
  InitSurfelsFromPoints(sphere, colors, 3, 1, &random, SurfelOrientation::kRandom);
  EXPECT_EQ(m.quats, qs);
  EXPECT_NE(random.quats, qs);
  // Too few points for a plane: identity.
  const std::vector<float> two = NeighbourhoodRotations({plane[0], plane[1]});
  EXPECT_EQ(two, (std::vector<float>{1, 0, 0, 0, 1, 0, 0, 0}));
}

// Points on a tilted plane spread to 7 times as many (an uneven share: 2801 over 400): each point
// kept, followed by its copies, every copy in the plane, within half its source's RMS 3-neighbour
// distance, in its colour; copies fill the disk (not all at the centre); seeded.
TEST(InitFromPointsTest, SpreadKeepsEachPointAndFillsItsDiskInItsSurface) {
  Rng rng(5);
  const Eigen::Vector3d normal = Eigen::Vector3d(0.3, -0.5, 1.0).normalized();
  const Eigen::Vector3d a = normal.unitOrthogonal(), b = normal.cross(a);
  std::vector<Eigen::Vector3f> points, colors;
  for (int i = 0; i < 400; ++i) {
    points.push_back((rng.Uniform() * a + rng.Uniform() * b + 0.2 * normal).cast<float>());
    colors.emplace_back(i / 400.0f, 0.5f, 1.0f - i / 400.0f);
  }
  const std::vector<float> d2 = MeanSquaredNeighbourDistance(points, 3);
  const size_t target = 2801;
  std::vector<Eigen::Vector3f> spread = points, spread_colors = colors;
  SpreadPointsOverTheirSurfaces(target, 9, &spread, &spread_colors);
  ASSERT_EQ(spread.size(), target);
  ASSERT_EQ(spread_colors.size(), target);
  size_t next = 0;
  double mean_r2 = 0;  // of the copies, in units of the disk radius squared
  size_t copies = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    ASSERT_EQ(spread[next], points[i]) << "point " << i << " kept, in order";
    const size_t share = target * (i + 1) / points.size() - target * i / points.size();
    EXPECT_TRUE(share == 7 || share == 8);
    const double radius = 0.5 * std::sqrt(d2[i]);
    for (size_t c = 0; c < share; ++c, ++next) {
      EXPECT_EQ(spread_colors[next], colors[i]);
      const Eigen::Vector3d offset = (spread[next] - points[i]).cast<double>();
      EXPECT_NEAR(offset.dot(normal), 0.0, 1e-5) << "in the plane";
      EXPECT_LE(offset.norm(), radius * (1 + 1e-5));
      if (c > 0) {
        mean_r2 += offset.squaredNorm() / (radius * radius);
        ++copies;
      }
    }
  }
  EXPECT_EQ(next, target);
  // Uniform in a disk: E[r^2] = R^2 / 2.
  EXPECT_NEAR(mean_r2 / copies, 0.5, 0.03);
  std::vector<Eigen::Vector3f> again = points, again_colors = colors, other = points,
                               other_colors = colors;
  SpreadPointsOverTheirSurfaces(target, 9, &again, &again_colors);
  SpreadPointsOverTheirSurfaces(target, 10, &other, &other_colors);
  EXPECT_EQ(again, spread);
  EXPECT_NE(other, spread);
}

TEST(InitFromPointsTest, SpreadLeavesPointsAloneWhenThereAreEnoughOrTooFew) {
  const auto grid = Grid(3, 0.1f);
  const std::vector<Eigen::Vector3f> grid_colors(grid.size(), Eigen::Vector3f(0.5f, 0.5f, 0.5f));
  for (const size_t target : {size_t{0}, grid.size() - 1, grid.size()}) {
    std::vector<Eigen::Vector3f> p = grid, c = grid_colors;
    SpreadPointsOverTheirSurfaces(target, 1, &p, &c);
    EXPECT_EQ(p, grid) << target;
    EXPECT_EQ(c, grid_colors) << target;
  }
  std::vector<Eigen::Vector3f> two = {grid[0], grid[1]},
                               two_colors = {grid_colors[0], grid_colors[1]};
  SpreadPointsOverTheirSurfaces(100, 1, &two, &two_colors);
  EXPECT_EQ(two.size(), 2u);
}

TEST(ParamBlockTest, BlocksCoverEveryFieldWithMatchingSizes) {
  GaussianModel g;
  g.max_sh_degree = 2;
  g.Resize(7);
  size_t floats = 0;
  for (const ParamBlock& b : g.Blocks()) {
    EXPECT_EQ(b.data->size(), 7u * b.width) << b.name;
    floats += b.data->size();
  }
  EXPECT_EQ(floats, 7u * (3 + 3 + 4 + 1 + 27 + 27 + 1 + 1));
  SurfelModel s;
  s.Resize(5);
  for (const ParamBlock& b : s.Blocks()) EXPECT_EQ(b.data->size(), 5u * b.width) << b.name;
}

TEST(ParamBlockTest, KeepAndAppendRowsMoveWholeRows) {
  GaussianModel g;
  g.max_sh_degree = 1;
  g.Resize(5);
  // Tag every value with its row.
  for (const ParamBlock& b : g.Blocks()) {
    for (size_t i = 0; i < b.data->size(); ++i) (*b.data)[i] = static_cast<float>(i / b.width);
  }
  g.KeepRows({1, 0, 1, 1, 0});
  ASSERT_EQ(g.size(), 3u);
  for (const ParamBlock& b : g.Blocks()) {
    ASSERT_EQ(b.data->size(), 3u * b.width);
    EXPECT_EQ((*b.data)[0], 0.0f) << b.name;
    EXPECT_EQ((*b.data)[b.width], 2.0f) << b.name;
    EXPECT_EQ((*b.data)[2 * b.width], 3.0f) << b.name;
  }
  g.AppendCopies({2, 0, 2});  // copies of old rows 3, 0, 3
  ASSERT_EQ(g.size(), 6u);
  for (const ParamBlock& b : g.Blocks()) {
    EXPECT_EQ((*b.data)[3 * b.width], 3.0f) << b.name;
    EXPECT_EQ((*b.data)[4 * b.width], 0.0f) << b.name;
    EXPECT_EQ((*b.data)[5 * b.width + b.width - 1], 3.0f) << b.name;
  }
}

}  // namespace
}  // namespace mgsr
