#include "mgsr/synth/synthetic_scene.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "mgsr/eval/closest_point.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/synth/ray_caster.h"
#include "mgsr/synth/shapes.h"
#include "test_util.h"

namespace mgsr {
namespace {

double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& f : m.triangles) {
    v += m.vertices[f[0]].dot(m.vertices[f[1]].cross(m.vertices[f[2]])) / 6.0;
  }
  return v;
}

double DistanceToMesh(const Eigen::Vector3d& p, const TriangleMesh& m) {
  double best = 1e300;
  for (const auto& f : m.triangles) {
    best = std::min(
        best, (p - ClosestPointOnTriangle(p, m.vertices[f[0]], m.vertices[f[1]], m.vertices[f[2]]))
                  .norm());
  }
  return best;
}

TEST(ShapesTest, ClosedOutwardAndInsideTheUnitSphere) {
  for (const std::string& name : ShapeNames()) {
    TriangleMesh m;
    ASSERT_TRUE(MakeShape(name, 0, &m)) << name;
    EXPECT_GT(SignedVolume(m), 0.05) << name << " must be wound outward";
    double max_r = 0;
    for (const auto& v : m.vertices) max_r = std::max(max_r, v.norm());
    EXPECT_LE(max_r, 1.0 + 1e-9) << name;
    // Smooth shapes shade with vertex normals; sharp-edged ones with their exact face normals.
    EXPECT_EQ(m.vertex_normals.size(), ShapeHasSharpEdges(name) ? 0u : m.vertices.size()) << name;
  }
  TriangleMesh sphere = MakeIcoSphere(0.8, 4);
  EXPECT_NEAR(SignedVolume(sphere), 4.0 / 3.0 * M_PI * 0.512, 0.01 * 4.0 / 3.0 * M_PI * 0.512);
  EXPECT_FALSE(MakeShape("teapot", 0, &sphere));
}

TEST(RayCasterTest, MatchesBruteForceAndAnalyticSphere) {
  const TriangleMesh m = MakeIcoSphere(0.8, 3);
  const RayCaster caster(m);
  RayHit hit;
  ASSERT_TRUE(caster.Intersect({0, 0, -5}, {0, 0, 1}, 0, 1e9, &hit));
  EXPECT_NEAR(hit.t, 4.2, 0.01);  // tessellation error of a 1280-triangle sphere
  EXPECT_FALSE(caster.Intersect({0, 0, -5}, {0, 1, 0}, 0, 1e9, &hit));
  EXPECT_TRUE(caster.Occluded({0, 0, -5}, {0, 0, 1}, 0, 1e9));
  EXPECT_FALSE(caster.Occluded({0, 0, -5}, {0, 0, 1}, 0, 4.0));
  // The BVH finds the same nearest hit as testing every triangle.
  const Eigen::Vector3d o(0.3, -2, 0.1);
  for (int k = 0; k < 50; ++k) {
    const Eigen::Vector3d d =
        Eigen::Vector3d(std::sin(k * 0.7) * 0.3, 1, std::cos(k * 1.3) * 0.3).normalized();
    double best = 1e300;
    for (const auto& f : m.triangles) {
      const Eigen::Vector3d a = m.vertices[f[0]], e1 = m.vertices[f[1]] - a,
                            e2 = m.vertices[f[2]] - a;
      Eigen::Matrix3d A;
      A << -d, e1, e2;
      const Eigen::Vector3d x = A.colPivHouseholderQr().solve(o - a);
      if (x[0] > 0 && x[1] >= 0 && x[2] >= 0 && x[1] + x[2] <= 1) best = std::min(best, x[0]);
    }
    const bool found = caster.Intersect(o, d, 0, 1e9, &hit);
    ASSERT_EQ(found, best < 1e300) << k;
    if (found) {
      EXPECT_NEAR(hit.t, best, 1e-9);
    }
  }
}

class SyntheticSceneTest : public ::testing::TestWithParam<std::string> {};

TEST_P(SyntheticSceneTest, GroundTruthIsConsistentWithImagesMasksAndCameras) {
  const std::string dir = testing::ScratchDir("_" + GetParam());
  SynthOptions o = testing::SmallSynthOptions();
  o.shape = GetParam();
  o.width = o.height = 64;
  ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
  // Read everything back through the public loaders, so the file conventions are what is tested.
  Scene scene;
  SceneOptions so;
  ASSERT_TRUE(LoadScene(dir, so, &scene).ok());
  TriangleMesh mesh;
  ASSERT_TRUE(ReadTriangleMesh(dir + "/gt/mesh.ply", &mesh).ok());
  // (A flat slab is 12 triangles; every other shape has hundreds.)
  ASSERT_GE(mesh.triangles.size(), 12u);

  // (1) The ground-truth mesh projects inside the masks for > 99% of vertices in every view.
  for (const View& v : scene.views) {
    int inside = 0;
    for (const auto& X : mesh.vertices) {
      const Eigen::Vector2d uv = v.camera.WorldToPixel(X);
      const int x = static_cast<int>(std::floor(uv.x())), y = static_cast<int>(std::floor(uv.y()));
      if (x < 0 || y < 0 || x >= v.mask.width() || y >= v.mask.height()) continue;
      // A vertex on the silhouette may fall in a partly covered pixel: look at the 3x3 block.
      bool hit = false;
      for (int dy = -1; dy <= 1 && !hit; ++dy) {
        for (int dx = -1; dx <= 1 && !hit; ++dx) {
          const int xx = std::clamp(x + dx, 0, v.mask.width() - 1),
                    yy = std::clamp(y + dy, 0, v.mask.height() - 1);
          hit = v.mask.at(0, yy, xx) > 0.5f;
        }
      }
      inside += hit;
    }
    EXPECT_GT(inside, 0.99 * mesh.vertices.size()) << v.name;
  }

  // (2) Depth pixels back-project onto the mesh within 1e-4 of the scene extent; normals are unit
  // and face the camera.
  for (int i : {1, 6}) {
    const View& v = scene.views[i];
    Image depth, normal;
    ASSERT_TRUE(ReadPfm(dir + "/gt/depth/" + FileStem(v.name) + ".pfm", &depth).ok());
    ASSERT_TRUE(ReadPfm(dir + "/gt/normal/" + FileStem(v.name) + ".pfm", &normal).ok());
    int checked = 0;
    for (int y = 0; y < depth.height(); y += 2) {
      for (int x = 0; x < depth.width(); x += 2) {
        const float z = depth.at(0, y, x);
        if (z <= 0) continue;
        const Eigen::Vector3d X = v.camera.CameraToWorld(v.camera.PixelToRay(x + 0.5, y + 0.5) * z);
        ASSERT_LT(DistanceToMesh(X, mesh), 1e-4 * scene.extent)
            << v.name << " pixel " << x << "," << y;
        const Eigen::Vector3d n(normal.at(0, y, x), normal.at(1, y, x), normal.at(2, y, x));
        EXPECT_NEAR(n.norm(), 1.0, 1e-5);
        EXPECT_LE(n.dot(X - v.camera.Center()), 1e-6);
        ++checked;
      }
    }
    EXPECT_GT(checked, 50) << "the object should cover a good part of the image";
  }
}

INSTANTIATE_TEST_SUITE_P(AllShapes, SyntheticSceneTest, ::testing::ValuesIn(ShapeNames()));

TEST(SyntheticSceneTest, DeterministicPerSeed) {
  const std::string dir = testing::ScratchDir();
  SynthOptions o = testing::SmallSynthOptions();
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/a").ok());
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/b").ok());
  o.seed = 2;
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/c").ok());
  std::string a, b, c;
  for (const char* f :
       {"images/v003.png", "sparse/0/images.bin", "sparse/0/points3D.bin", "lights.json"}) {
    ASSERT_TRUE(ReadFileToString(dir + "/a/" + f, &a).ok());
    ASSERT_TRUE(ReadFileToString(dir + "/b/" + f, &b).ok());
    ASSERT_TRUE(ReadFileToString(dir + "/c/" + f, &c).ok());
    EXPECT_EQ(a, b) << f;
    EXPECT_NE(a, c) << f;
  }
}

TEST(SyntheticSceneTest, LightVariesPerViewAndConstantCopyDoesNot) {
  const std::string dir = testing::ScratchDir();
  SynthOptions o = testing::SmallSynthOptions();
  o.constant_light_copy = true;
  o.exposure_stops = 2.0;
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/varied").ok());
  o.varying_light = false;
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/fixed").ok());
  auto mean_brightness = [&](const std::string& path) {
    Image im;
    EXPECT_TRUE(ReadImage(path, &im).ok()) << path;
    double sum = 0, n = 0;
    for (size_t k = 0; k < im.plane_size(); ++k) {
      if (im.plane(3)[k] < 1) continue;
      sum += im.plane(0)[k] + im.plane(1)[k] + im.plane(2)[k];
      n += 3;
    }
    return sum / std::max(1.0, n);
  };
  // Same viewpoint, varied light vs the fixed light: the brightness ratio spreads across views.
  double lo = 1e9, hi = 0;
  for (int i = 0; i < o.num_views; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "v%03d.png", i);
    const double ratio = mean_brightness(dir + "/varied/images/" + name) /
                         mean_brightness(dir + "/varied/images_constant/" + name);
    lo = std::min(lo, ratio);
    hi = std::max(hi, ratio);
    // Without light variation, the images are the constant-light renders exactly.
    std::string a, b;
    ASSERT_TRUE(ReadFileToString(dir + "/fixed/images/" + name, &a).ok());
    ASSERT_TRUE(ReadFileToString(dir + "/fixed/images_constant/" + name, &b).ok());
    EXPECT_EQ(a, b) << name;
  }
  EXPECT_GT(hi / lo, 2.0);
  // Without masks the copy is written as the photos are (over grey, no alpha), so it can stand in
  // for images/: under a fixed light the two are the same files.
  o.masks = false;
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/unmasked").ok());
  for (int i = 0; i < o.num_views; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "v%03d.png", i);
    std::string a, b;
    ASSERT_TRUE(ReadFileToString(dir + "/unmasked/images/" + name, &a).ok());
    ASSERT_TRUE(ReadFileToString(dir + "/unmasked/images_constant/" + name, &b).ok());
    EXPECT_EQ(a, b) << name;
    Image im;
    ASSERT_TRUE(ReadImage(dir + "/unmasked/images_constant/" + name, &im).ok());
    EXPECT_EQ(im.channels(), 3) << name;
  }
}

// The stress variants of the benchmark suite: noisy recorded poses (images from the true ones) and
// photos without masks.
TEST(SyntheticSceneTest, NoisyPosesAndNoMasks) {
  const std::string dir = testing::ScratchDir();
  SynthOptions o = testing::SmallSynthOptions();
  o.num_views = 20;
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/clean").ok());
  o.pose_noise_deg = 1.0;
  o.pose_noise_rel = 0.01;
  o.masks = false;
  ASSERT_TRUE(WriteSyntheticScene(o, dir + "/noisy").ok());
  Scene clean, noisy;
  ASSERT_TRUE(LoadScene(dir + "/clean", SceneOptions(), &clean).ok());
  ASSERT_TRUE(LoadScene(dir + "/noisy", SceneOptions(), &noisy).ok());
  EXPECT_TRUE(clean.has_masks());
  EXPECT_FALSE(noisy.has_masks());
  EXPECT_FALSE(DirectoryExists(dir + "/noisy/masks"));
  EXPECT_TRUE(noisy.views[0].alpha.empty());
  double rms_rot = 0, rms_center = 0;
  for (size_t i = 0; i < clean.views.size(); ++i) {
    const Camera& t = clean.views[i].camera;
    const Camera& n = noisy.views[i].camera;
    const double angle = Eigen::AngleAxisd(n.R * t.R.transpose()).angle() * 180 / M_PI;
    rms_rot += angle * angle / clean.views.size();
    rms_center += (n.Center() - t.Center()).squaredNorm() / clean.views.size();
  }
  // rms 1 degree and 1% of the 3.5 distance, within sampling spread of 20 draws.
  EXPECT_NEAR(std::sqrt(rms_rot), 1.0, 0.4);
  EXPECT_NEAR(std::sqrt(rms_center), 0.035, 0.015);
  // Same photos apart from the background: the object pixels agree.
  const View& c0 = clean.views[3];
  const View& n0 = noisy.views[3];
  int checked = 0;
  for (size_t k = 0; k < c0.alpha.size(); ++k) {
    if (c0.alpha.data()[k] < 1.0f) continue;
    for (int ch = 0; ch < 3; ++ch)
      EXPECT_NEAR(c0.image.plane(ch)[k], n0.image.plane(ch)[k], 1.0f / 255);
    ++checked;
  }
  EXPECT_GT(checked, 50);
}

TEST(SyntheticSceneTest, OptionsAreValidated) {
  SynthOptions o;
  o.shape = "teapot";
  Status s = o.Validate();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("unknown shape 'teapot'"), std::string::npos);
  o = SynthOptions();
  o.num_views = 1;
  EXPECT_FALSE(o.Validate().ok());
  o = SynthOptions();
  o.mirror = 2;
  EXPECT_FALSE(o.Validate().ok());
}

}  // namespace
}  // namespace mgsr
