// Free space from the fused views (mgsr/mesh/seen_through.h): the vote on known depth maps, and
// in the TSDF, a floater that one view shows and the others see through.
#include "mgsr/mesh/seen_through.h"

#include <gtest/gtest.h>

#include <vector>

#include "mgsr/mesh/tsdf_fusion.h"
#include "test_util.h"

namespace mgsr {
namespace {

// Cameras around -y, all looking at the origin; the plane y = 0 is what they see.
std::vector<Camera> Cameras(int n, int size = 48) {
  std::vector<Camera> cams;
  for (int i = 0; i < n; ++i) {
    const double a = -0.5 + 1.0 * i / std::max(1, n - 1);
    cams.push_back(LookAtCamera({3 * std::sin(a), -3 * std::cos(a), 0.4 * (i % 2)}, {0, 0, 0},
                                Eigen::Vector3d::UnitZ(), size, size, size, size));
  }
  return cams;
}

// The z-depth of the plane y = 0 where it lies inside |x|, |z| < half (0 elsewhere).
Image PlaneDepth(const Camera& cam, double half = 0.6) {
  Image d(cam.width, cam.height, 1, 0.0f);
  const Eigen::Vector3d C = cam.Center();
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const Eigen::Vector3d w = cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5);
      const double t = -C.y() / w.y();  // w has camera z = 1: t is the z-depth
      const Eigen::Vector3d X = C + t * w;
      if (t > 0 && std::abs(X.x()) < half && std::abs(X.z()) < half)
        d.at(0, y, x) = static_cast<float>(t);
    }
  }
  return d;
}

std::vector<float> Depths(const Image& depth) {
  return std::vector<float>(depth.data(), depth.data() + depth.size());
}

TEST(SeenThroughVotesTest, AVertexGoesWhenMoreViewsSeeThroughItThanHoldIt) {
  const std::vector<Camera> cams = Cameras(5);
  SeenThroughVotes votes;
  for (const Camera& c : cams) votes.AddView(c, Depths(PlaneDepth(c)));
  const double band = 0.05;
  const std::vector<Eigen::Vector3d> vertices = {
      {0.1, 0.0, 0.05},    // on the plane: every view holds it
      {0.1, -0.5, 0.05},   // in front of the plane: every view sees the plane behind it
      {0.1, 0.03, 0.05},   // behind the plane within the band: held
      {0.1, 0.5, 0.05},    // behind the plane: hidden, not seen through
      {0.0, 0.0, 5.0},     // outside every frame: no vote
      {0.58, 0.0, 0.05}};  // on the plane at its rim: held where its pixel has depth
  std::vector<Eigen::Vector3i> triangles;
  for (int i = 0; i < static_cast<int>(vertices.size()); ++i) triangles.emplace_back(i, i, i);
  SeenThroughStats stats;
  const std::vector<bool> removed = votes.TrianglesSeenThrough(vertices, triangles, band, &stats);
  EXPECT_EQ(removed, (std::vector<bool>{false, true, false, false, false, false}));
  EXPECT_EQ(stats.removed_vertices, 1u);
  EXPECT_EQ(stats.removed_triangles, 1u);

  // Views that render nothing see through everything in their frame: with three of them against
  // the five that hold the plane, the plane stays; with six, it goes.
  const Image nothing(48, 48, 1, 0.0f);
  for (int k = 0; k < 3; ++k) votes.AddView(Cameras(3)[k], Depths(nothing));
  EXPECT_FALSE(votes.TrianglesSeenThrough(vertices, triangles, band)[0]);
  for (int k = 0; k < 3; ++k) votes.AddView(Cameras(3)[k], Depths(nothing));
  EXPECT_TRUE(votes.TrianglesSeenThrough(vertices, triangles, band)[0]);

  // One pixel of slack: an empty pixel next to one with depth at the vertex does not see through
  // it (a surface's own outline).
  SeenThroughVotes edge;
  const Camera& c = cams[2];
  Image d = PlaneDepth(c);
  const Eigen::Vector3d on_plane(0.1, 0.0, 0.05);
  const Eigen::Vector2d p = c.WorldToPixel(on_plane);
  const int px = static_cast<int>(p.x());
  for (int y = 0; y < d.height(); ++y)
    for (int x = px; x < d.width(); ++x) d.at(0, y, x) = 0;  // empty from the vertex's column on
  edge.AddView(c, Depths(d));
  EXPECT_FALSE(edge.TrianglesSeenThrough({on_plane}, {{0, 0, 0}}, band)[0]);
  for (int y = 0; y < d.height(); ++y) d.at(0, y, px - 1) = 0;  // and the column before it
  SeenThroughVotes gap;
  gap.AddView(c, Depths(d));
  EXPECT_TRUE(gap.TrianglesSeenThrough({on_plane}, {{0, 0, 0}}, band)[0]);
}

// Five views of a plane; one of them also shows a small sheet in front of it (what a few
// backdrop-coloured disks give). The TSDF meshes the sheet; the other four views see the plane
// behind it, so the free-space test removes it and leaves the plane.
TEST(SeenThroughVotesTest, TheFusionDropsASheetOneViewShowsAndTheOthersSeeThrough) {
  const std::vector<Camera> cams = Cameras(5, 64);
  std::vector<DepthFrame> frames;
  for (const Camera& c : cams) {
    DepthFrame f;
    f.camera = c;
    f.depth = PlaneDepth(c);
    frames.push_back(f);
  }
  // The sheet in view 0: a 10 x 10 pixel square at z-depth 2.2, 0.8 in front of the plane.
  for (int y = 10; y < 20; ++y)
    for (int x = 12; x < 22; ++x) frames[0].depth.at(0, y, x) = 2.2f;
  TsdfOptions options;
  options.voxel_size = 0.02;
  auto in_front = [](const TriangleMesh& m) {
    int n = 0;
    for (const auto& v : m.vertices) n += v.y() < -0.3;
    return n;
  };
  auto on_plane = [](const TriangleMesh& m) {
    int n = 0;
    for (const auto& v : m.vertices) n += std::abs(v.y()) < 0.05;
    return n;
  };
  TriangleMesh kept, carved;
  options.free_space = false;
  ASSERT_TRUE(FuseDepthMaps(frames, options, &kept).ok());
  options.free_space = true;
  TsdfIntegrator integrator(options);
  for (const DepthFrame& f : frames) ASSERT_TRUE(integrator.Integrate(f).ok());
  ASSERT_TRUE(integrator.Extract(&carved).ok());
  EXPECT_GT(in_front(kept), 50);
  EXPECT_EQ(in_front(carved), 0);
  // The plane loses nothing but vertices the sheet's TSDF band reached (a few near its shadow).
  EXPECT_GT(on_plane(carved), 0.97 * on_plane(kept));
  EXPECT_GT(integrator.seen_through().removed_vertices, 50u);
  EXPECT_EQ(carved.vertices.size(), carved.vertex_colors.size());
}

}  // namespace
}  // namespace mgsr
