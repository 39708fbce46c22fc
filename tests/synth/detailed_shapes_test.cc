// The detailed built-in shapes are closed, outward-wound solids inside the unit sphere, and mesh
// files (OBJ) become scenes like the built-in shapes.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <utility>

#include "mgsr/io/file_util.h"
#include "mgsr/io/mesh_obj.h"
#include "mgsr/synth/shapes.h"
#include "mgsr/synth/synthetic_scene.h"
#include "test_util.h"

namespace mgsr {
namespace {

// Every directed edge appears exactly once and its reverse exactly once: closed and consistently
// wound.
bool IsClosedAndConsistent(const TriangleMesh& m, std::string* why) {
  std::map<std::pair<int, int>, int> directed;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  for (const auto& [edge, count] : directed) {
    if (count != 1) {
      *why = "edge used " + std::to_string(count) + " times in one direction";
      return false;
    }
    if (directed.find({edge.second, edge.first}) == directed.end()) {
      *why = "open edge";
      return false;
    }
  }
  return true;
}

double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles)
    v += m.vertices[t[0]].dot(m.vertices[t[1]].cross(m.vertices[t[2]])) / 6.0;
  return v;
}

TEST(DetailedShapesTest, ClosedOutwardAndInsideTheUnitSphere) {
  for (const std::string name : {"gear", "slot", "knot", "wall"}) {
    for (int detail = 0; detail <= 1; ++detail) {
      SCOPED_TRACE(name + " detail " + std::to_string(detail));
      TriangleMesh m;
      ASSERT_TRUE(MakeShape(name, detail, &m));
      std::string why;
      EXPECT_TRUE(IsClosedAndConsistent(m, &why)) << why;
      EXPECT_GT(SignedVolume(m), 0.01) << "outward winding";
      for (const auto& p : m.vertices) EXPECT_LE(p.norm(), 1.0);
    }
  }
  // Concave shapes are not their convex hull: the gear's and the slot's volume is well below the
  // box around them (a rough check that the grooves and the slot are there).
  TriangleMesh gear, slot;
  MakeShape("gear", 1, &gear);
  MakeShape("slot", 1, &slot);
  // Gear: annulus of root 0.62 and hole 0.25 plus 14 teeth, 0.44 thick.
  const double expected_min = M_PI * (0.62 * 0.62 - 0.25 * 0.25) * 0.44;
  EXPECT_GT(SignedVolume(gear), expected_min);
  EXPECT_LT(SignedVolume(gear), M_PI * 0.86 * 0.86 * 0.44);
  // Slot: 1.24 x 1.08 x 0.8 minus the 0.1 x 0.9 x 0.8 slot.
  EXPECT_NEAR(SignedVolume(slot), 1.24 * 1.08 * 0.8 - 0.1 * 0.9 * 0.8, 1e-9);
}

TEST(MeshObjTest, ReadsPolygonsAndRefusesBadFiles) {
  const std::string dir = testing::ScratchDir();
  const std::string good = JoinPath(dir, "quad.obj");
  {
    std::ofstream f(good);
    f << "# a square and a triangle\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\n"
         "f 1/1/1 2/2/1 3/3/1 4/4/1\nf -4 -3 -1\n";
  }
  TriangleMesh m;
  ASSERT_TRUE(ReadMeshFile(good, &m).ok());
  EXPECT_EQ(m.vertices.size(), 4u);
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[2], Eigen::Vector3i(0, 1, 3));
  const std::pair<const char*, const char*> bad[] = {
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\n", "out of range"},
      {"v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3"},
      {"v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "finite"},
      {"v 0 0 1e39\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "finite"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 3\n", "bad face index"},
      {"v 0 0 0\n", "no faces"}};
  for (const auto& [text, message] : bad) {
    const std::string path = JoinPath(dir, "bad.obj");
    std::ofstream(path) << text;
    const Status s = ReadMeshFile(path, &m);
    ASSERT_FALSE(s.ok()) << text;
    EXPECT_NE(s.message().find(message), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("bad.obj"), std::string::npos) << s.message();
  }
}

TEST(MeshObjTest, AMeshFileBecomesASceneScaledToTheUnitSphere) {
  const std::string dir = testing::ScratchDir();
  const std::string path = JoinPath(dir, "tetra.obj");
  std::ofstream(path) << "v 10 10 10\nv 14 10 10\nv 10 14 10\nv 10 10 14\n"
                         "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  SynthOptions o;
  o.mesh_path = path;
  o.num_views = 6;
  o.width = o.height = 24;
  SyntheticScene s;
  ASSERT_TRUE(MakeSyntheticScene(o, &s).ok());
  double far = 0;
  for (const auto& p : s.layout.ground_truth.vertices) far = std::max(far, p.norm());
  EXPECT_NEAR(far, 1.0, 1e-9);
  o.mesh_path = JoinPath(dir, "missing.obj");
  const Status missing = MakeSyntheticScene(o, &s);
  EXPECT_FALSE(missing.ok());
  EXPECT_NE(missing.message().find("missing.obj"), std::string::npos);
}

// A scene written over an older one replaces it whole (no old photo stays); a folder holding
// anything else is refused.
TEST(SceneFolderTest, ASceneReplacesAnOlderSceneAndNothingElse) {
  const std::string dir = testing::ScratchDir() + "/scene";
  SynthOptions o = testing::SmallSynthOptions();
  ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
  o.num_views = 6;
  o.masks = false;
  ASSERT_TRUE(WriteSyntheticScene(o, dir).ok());
  size_t images = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir + "/images"))
    images += !e.path().empty();
  EXPECT_EQ(images, 6u);
  EXPECT_FALSE(std::filesystem::exists(dir + "/masks"));
  const std::string other = testing::ScratchDir() + "/other";
  std::filesystem::create_directories(other);
  std::ofstream(other + "/notes.txt") << "mine";
  const Status s = WriteSyntheticScene(o, other);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("holds no scene of mgsr_synth"), std::string::npos) << s.message();
  EXPECT_TRUE(std::filesystem::exists(other + "/notes.txt"));
}

}  // namespace
}  // namespace mgsr
