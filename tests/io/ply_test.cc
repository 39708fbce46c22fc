#include "mgsr/io/ply.h"

#include <gtest/gtest.h>

#include "mgsr/core/rng.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/synth/shapes.h"
#include "test_util.h"

namespace mgsr {
namespace {

TEST(PlyTest, MeshRoundTripBinaryAndAscii) {
  const std::string dir = testing::ScratchDir();
  TriangleMesh mesh = MakeTorus(0.6, 0.2, 12, 8);
  for (size_t i = 0; i < mesh.vertices.size(); ++i)
    mesh.vertex_colors.emplace_back((i % 256) / 255.0f, 128 / 255.0f, 1.0f);
  for (PlyFormat f : {PlyFormat::kBinaryLittleEndian, PlyFormat::kAscii}) {
    const std::string path = dir + (f == PlyFormat::kAscii ? "/a.ply" : "/b.ply");
    ASSERT_TRUE(WriteTriangleMesh(path, mesh, f).ok());
    TriangleMesh back;
    ASSERT_TRUE(ReadTriangleMesh(path, &back).ok());
    ASSERT_EQ(back.vertices.size(), mesh.vertices.size());
    ASSERT_EQ(back.triangles, mesh.triangles);
    ASSERT_EQ(back.vertex_normals.size(), mesh.vertices.size());
    ASSERT_EQ(back.vertex_colors.size(), mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      EXPECT_NEAR((back.vertices[i] - mesh.vertices[i]).norm(), 0, 1e-6);
      EXPECT_NEAR((back.vertex_normals[i] - mesh.vertex_normals[i]).norm(), 0, 1e-6);
      EXPECT_NEAR((back.vertex_colors[i] - mesh.vertex_colors[i]).norm(), 0, 1e-6);
    }
  }
}

TEST(PlyTest, GenericRewriteIsByteIdentical) {
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(WriteTriangleMesh(dir + "/m.ply", MakeIcoSphere(1, 1)).ok());
  PlyData ply;
  ASSERT_TRUE(ReadPly(dir + "/m.ply", &ply).ok());
  ASSERT_TRUE(WritePly(dir + "/m2.ply", ply).ok());
  std::string a, b;
  ASSERT_TRUE(ReadFileToString(dir + "/m.ply", &a).ok());
  ASSERT_TRUE(ReadFileToString(dir + "/m2.ply", &b).ok());
  EXPECT_EQ(a, b);
}

TEST(PlyTest, PolygonsAreTriangulatedAndPointCloudsRead) {
  const std::string dir = testing::ScratchDir();
  const std::string quad =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float "
      "z\n"
      "element face 1\nproperty list uchar int vertex_index\nend_header\n"
      "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/quad.ply", quad).ok());
  TriangleMesh m;
  ASSERT_TRUE(ReadTriangleMesh(dir + "/quad.ply", &m).ok());
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_DOUBLE_EQ(m.SurfaceArea(), 1.0);
  const std::string cloud =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty "
      "double z\n"
      "end_header\n1 2 3\n4 5 6\n";
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/cloud.ply", cloud).ok());
  ASSERT_TRUE(ReadTriangleMesh(dir + "/cloud.ply", &m).ok());
  EXPECT_EQ(m.vertices.size(), 2u);
  EXPECT_TRUE(m.triangles.empty());
}

TEST(PlyTest, BadFilesGiveClearErrors) {
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(WriteTriangleMesh(dir + "/m.ply", MakeIcoSphere(1, 2)).ok());
  std::string full;
  ASSERT_TRUE(ReadFileToString(dir + "/m.ply", &full).ok());
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/cut.ply", full.substr(0, full.size() - 100)).ok());
  TriangleMesh m;
  Status s = ReadTriangleMesh(dir + "/cut.ply", &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(dir + "/cut.ply: truncated"), std::string::npos) << s.message();
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/nothing.ply", "hello").ok());
  s = ReadTriangleMesh(dir + "/nothing.ply", &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("not a PLY file"), std::string::npos);
  const std::string bad_index =
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float "
      "z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 7\n";
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/idx.ply", bad_index).ok());
  s = ReadTriangleMesh(dir + "/idx.ply", &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("refers to vertex 1 of 1"), std::string::npos) << s.message();
  // What a float32 file cannot hold, face indices that are not integers, faces of fewer than
  // three vertices: each refused by name.
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty "
      "float z\nelement face 1\n";
  const std::pair<std::string, std::string> cases[] = {
      {head + "property list uchar int vertex_indices\nend_header\n0 0 0\n1e39 0 0\n0 1 0\n3 0 "
              "1 2\n",
       "property 'x' is out of range for float"},
      {head + "property list uchar float vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 "
              "1 2\n",
       "face indices are declared float; they must be an integer type"},
      {head + "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
       "face 0 has 2 vertices (at least 3)"}};
  for (const auto& [text, expected] : cases) {
    ASSERT_TRUE(WriteStringToFileAtomic(dir + "/case.ply", text).ok());
    s = ReadTriangleMesh(dir + "/case.ply", &m);
    ASSERT_FALSE(s.ok()) << expected;
    EXPECT_NE(s.message().find(expected), std::string::npos) << s.message();
  }
}

// Found by fuzzing (#18): a list where a scalar belongs crashed the readers, and a small header
// declaring many properties over many items demanded gigabytes before reading a byte.
TEST(PlyTest, ListPropertiesAndOversizedHeadersAreRefused) {
  const std::string dir = testing::ScratchDir();
  TriangleMesh m;
  for (const std::string name : {"x", "nx", "red"}) {
    std::string ply = "ply\nformat ascii 1.0\nelement vertex 1\n";
    for (const std::string p : {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"}) {
      ply += p == name ? "property list uchar float " + p + "\n" : "property float " + p + "\n";
    }
    ply += "end_header\n1 0.5 0 0 0 0 1 0 0 0\n";
    const std::string path = dir + "/list_" + name + ".ply";
    ASSERT_TRUE(WriteStringToFileAtomic(path, ply).ok());
    const Status s = ReadTriangleMesh(path, &m);
    ASSERT_FALSE(s.ok()) << name;
    EXPECT_EQ(s.message(),
              path + ": property '" + name + "' of element 'vertex' is a list, expected a scalar");
    GaussianModel g;
    EXPECT_FALSE(ReadGaussianPly(path, &g).ok());  // the model readers go through the same check
  }
  // 3,000 double properties over 100,000 vertices: 2.4 GB of doubles from a 60 kB file.
  std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex 100000\n";
  for (int p = 0; p < 3000; ++p) header += "property double p" + std::to_string(p) + "\n";
  header += "end_header\n" + std::string(1000, '\0');
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/huge.ply", header).ok());
  const Status s = ReadTriangleMesh(dir + "/huge.ply", &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("more than the file can hold"), std::string::npos) << s.message();
  // The same in ASCII, where a value takes at least a byte.
  std::string ascii = "ply\nformat ascii 1.0\nelement vertex 100000\n";
  for (int p = 0; p < 3000; ++p) ascii += "property float p" + std::to_string(p) + "\n";
  ascii += "end_header\n" + std::string(1000, '1');
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/huge_ascii.ply", ascii).ok());
  EXPECT_FALSE(ReadTriangleMesh(dir + "/huge_ascii.ply", &m).ok());
}

TEST(PlyTest, GaussianPlyRoundTripHasStandardNames) {
  const std::string dir = testing::ScratchDir();
  Rng rng(7);
  GaussianModel g;
  g.Resize(5);
  for (auto* v : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh, &g.ref_sh,
                  &g.ref_opacity_logits, &g.beta_logits}) {
    for (float& x : *v) x = static_cast<float>(rng.Normal());
  }
  ASSERT_TRUE(WriteGaussianPly(dir + "/g.ply", g).ok());
  PlyData ply;
  ASSERT_TRUE(ReadPly(dir + "/g.ply", &ply).ok());
  const PlyElement* v = ply.FindElement("vertex");
  ASSERT_NE(v, nullptr);
  // The attribute order of the original 3DGS writer, then ours.
  const char* expected[] = {"x",  "y",      "z",      "nx",     "ny",
                            "nz", "f_dc_0", "f_dc_1", "f_dc_2", "f_rest_0"};
  for (int i = 0; i < 10; ++i) EXPECT_EQ(v->properties[i].name, expected[i]);
  EXPECT_EQ(v->properties[6 + 3 + 45].name, "opacity");
  EXPECT_GE(v->FindProperty("rot_3"), 0);
  EXPECT_GE(v->FindProperty("ref_f_rest_44"), 0);
  EXPECT_GE(v->FindProperty("beta"), 0);
  // f_rest is channel-major: f_rest_15 is coefficient 1 of green.
  EXPECT_FLOAT_EQ(static_cast<float>(v->columns[v->FindProperty("f_rest_15")][2]),
                  g.sh[2 * 48 + 1 * 3 + 1]);

  GaussianModel back;
  ASSERT_TRUE(ReadGaussianPly(dir + "/g.ply", &back).ok());
  EXPECT_EQ(back.means, g.means);
  EXPECT_EQ(back.log_scales, g.log_scales);
  EXPECT_EQ(back.quats, g.quats);
  EXPECT_EQ(back.opacity_logits, g.opacity_logits);
  EXPECT_EQ(back.sh, g.sh);
  EXPECT_EQ(back.ref_sh, g.ref_sh);
  EXPECT_EQ(back.ref_opacity_logits, g.ref_opacity_logits);
  EXPECT_EQ(back.beta_logits, g.beta_logits);
}

TEST(PlyTest, SurfelPlyRoundTripAndLowerShDegree) {
  const std::string dir = testing::ScratchDir();
  SurfelModel s;
  s.max_sh_degree = 1;
  s.Resize(4);
  Rng rng(9);
  for (auto* v : {&s.means, &s.log_scales, &s.quats, &s.opacity_logits, &s.sh}) {
    for (float& x : *v) x = static_cast<float>(rng.Normal());
  }
  ASSERT_TRUE(WriteSurfelPly(dir + "/s.ply", s).ok());
  SurfelModel back;
  ASSERT_TRUE(ReadSurfelPly(dir + "/s.ply", &back).ok());
  EXPECT_EQ(back.max_sh_degree, 1);
  EXPECT_EQ(back.means, s.means);
  EXPECT_EQ(back.log_scales, s.log_scales);
  EXPECT_EQ(back.quats, s.quats);
  EXPECT_EQ(back.sh, s.sh);
  // A surfel file is not a 3DGS file and vice versa.
  GaussianModel g;
  g.Resize(2);
  ASSERT_TRUE(WriteGaussianPly(dir + "/g.ply", g).ok());
  const Status st = ReadSurfelPly(dir + "/g.ply", &back);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("3DGS file"), std::string::npos);
}

TEST(PlyTest, ReadsTheSharedGroundTruthMesh) {
  if (!testing::HaveSharedData()) GTEST_SKIP() << "../shared/data not present";
  TriangleMesh m;
  ASSERT_TRUE(ReadTriangleMesh(testing::SharedDataDir() + "/suzanne/gt_mesh.ply", &m).ok());
  EXPECT_GT(m.triangles.size(), 1000u);
  double max_r = 0;
  for (const auto& v : m.vertices) max_r = std::max(max_r, v.norm());
  EXPECT_NEAR(max_r, 1.0, 1e-3);  // normalised so the farthest vertex is at radius 1
}

}  // namespace
}  // namespace mgsr
