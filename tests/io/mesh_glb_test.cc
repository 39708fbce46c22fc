#include "mgsr/io/mesh_glb.h"

#include <gtest/gtest.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>

#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>
#include <sstream>

#include "mgsr/core/rng.h"
#include "mgsr/core/subprocess.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/ply.h"
#include "mgsr/synth/shapes.h"
#include "test_util.h"

namespace mgsr {
namespace {

// A torus (not symmetric under the axis swaps a wrong writer might make) with a colour gradient
// over x that spans dark and bright values (both branches of the sRGB curve).
TriangleMesh ColouredTorus() {
  TriangleMesh m = MakeTorus(0.7, 0.25, 24, 12);
  for (const Eigen::Vector3d& v : m.vertices) {
    const float t = static_cast<float>((v.x() + 1.0) / 2.0);
    m.vertex_colors.emplace_back(t, 1.0f - t, 0.02f + 0.5f * t * t);
  }
  return m;
}

float SrgbToLinear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

// The JSON chunk of a .glb (its layout checked on the way).
nlohmann::json JsonChunk(const std::string& bytes) {
  uint32_t header[5];
  EXPECT_GE(bytes.size(), sizeof(header));
  std::memcpy(header, bytes.data(), sizeof(header));
  EXPECT_EQ(header[0], 0x46546C67u);  // "glTF"
  EXPECT_EQ(header[1], 2u);
  EXPECT_EQ(header[2], bytes.size());
  EXPECT_EQ(header[3] % 4, 0u);       // chunks stay 4-byte aligned
  EXPECT_EQ(header[4], 0x4E4F534Au);  // "JSON"
  return nlohmann::json::parse(bytes.substr(20, header[3]));
}

TEST(MeshGlbTest, RoundTripKeepsGeometryColoursAndUnitNormals) {
  const std::string dir = testing::ScratchDir();
  const TriangleMesh mesh = ColouredTorus();
  ASSERT_TRUE(WriteMeshGlb(dir + "/m.glb", mesh).ok());
  TriangleMesh back;
  const Status s = ReadMeshGlb(dir + "/m.glb", &back);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(back.vertices.size(), mesh.vertices.size());
  ASSERT_EQ(back.triangles.size(), mesh.triangles.size());
  ASSERT_EQ(back.vertex_colors.size(), mesh.vertex_colors.size());
  ASSERT_EQ(back.vertex_normals.size(), mesh.vertices.size());
  TriangleMesh with_normals = mesh;
  with_normals.ComputeVertexNormals();
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    EXPECT_LT((back.vertices[i] - mesh.vertices[i]).norm(), 1e-6) << i;
    EXPECT_LT((back.vertex_colors[i] - mesh.vertex_colors[i]).norm(), 1e-5) << i;
    EXPECT_NEAR(back.vertex_normals[i].norm(), 1.0, 1e-6) << i;
    EXPECT_GT(back.vertex_normals[i].dot(with_normals.vertex_normals[i].normalized()), 0.99999);
  }
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    EXPECT_EQ(back.triangles[t], mesh.triangles[t]);
}

TEST(MeshGlbTest, LayoutBoundsAndMaterialAreWhatViewersNeed) {
  const std::string dir = testing::ScratchDir();
  const TriangleMesh mesh = ColouredTorus();
  ASSERT_TRUE(WriteMeshGlb(dir + "/m.glb", mesh).ok());
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(dir + "/m.glb", &bytes).ok());
  const nlohmann::json j = JsonChunk(bytes);
  EXPECT_EQ(j["asset"]["version"], "2.0");
  const nlohmann::json& prim = j["meshes"][0]["primitives"][0];
  const nlohmann::json& pos = j["accessors"][prim["attributes"]["POSITION"].get<int>()];
  for (int d = 0; d < 3; ++d) {
    float lo = 1e9f, hi = -1e9f;
    for (const Eigen::Vector3d& v : mesh.vertices) {
      lo = std::min(lo, static_cast<float>(v[d]));
      hi = std::max(hi, static_cast<float>(v[d]));
    }
    EXPECT_EQ(pos["min"][d].get<float>(), lo);  // validators compare exactly with the data
    EXPECT_EQ(pos["max"][d].get<float>(), hi);
  }
  // glTF's default material is fully metallic: vertex colours would render near black.
  EXPECT_EQ(j["materials"][prim["material"].get<int>()]["pbrMetallicRoughness"]["metallicFactor"],
            0.0);
  EXPECT_EQ(j["accessors"][prim["indices"].get<int>()]["count"], mesh.triangles.size() * 3);
}

// Open3D's reader (tinygltf) is a third-party reader: the same geometry, and the linear colours
// glTF defines (the sRGB decoding of ours).
TEST(MeshGlbTest, Open3DReadsOurGlbAndOurPly) {
  const std::string dir = testing::ScratchDir();
  const TriangleMesh mesh = ColouredTorus();
  ASSERT_TRUE(WriteMeshGlb(dir + "/m.glb", mesh).ok());
  ASSERT_TRUE(WriteTriangleMesh(dir + "/m.ply", mesh).ok());
  for (const char* name : {"m.glb", "m.ply"}) {
    SCOPED_TRACE(name);
    open3d::geometry::TriangleMesh o3d;
    ASSERT_TRUE(open3d::io::ReadTriangleMesh(dir + "/" + name, o3d));
    ASSERT_EQ(o3d.vertices_.size(), mesh.vertices.size());
    ASSERT_EQ(o3d.triangles_.size(), mesh.triangles.size());
    ASSERT_EQ(o3d.vertex_colors_.size(), mesh.vertices.size());
    const bool linear = std::string(name) == "m.glb";
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      EXPECT_LT((o3d.vertices_[i] - mesh.vertices[i]).norm(), 1e-6) << i;
      for (int d = 0; d < 3; ++d) {
        const float c = mesh.vertex_colors[i][d];
        EXPECT_NEAR(o3d.vertex_colors_[i][d], linear ? SrgbToLinear(c) : c, 0.003) << i;
      }
    }
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
      EXPECT_EQ(o3d.triangles_[t], mesh.triangles[t]) << t;
  }
}

TEST(MeshGlbTest, BadFilesAreOneLineErrorsNamingTheFile) {
  const std::string dir = testing::ScratchDir();
  ASSERT_TRUE(WriteMeshGlb(dir + "/m.glb", ColouredTorus()).ok());
  std::string good;
  ASSERT_TRUE(ReadFileToString(dir + "/m.glb", &good).ok());
  TriangleMesh out;
  EXPECT_FALSE(WriteMeshGlb(dir + "/empty.glb", TriangleMesh()).ok());
  EXPECT_FALSE(FileExists(dir + "/empty.glb"));

  std::string bad_magic = good;
  bad_magic[0] = 'x';
  // Every prefix of the file, a wrong magic, and an index past the vertices.
  std::vector<std::pair<std::string, std::string>> cases = {{"bad_magic.glb", bad_magic}};
  for (size_t cut : {size_t{0}, size_t{7}, size_t{20}, good.size() / 2, good.size() - 4})
    cases.emplace_back("cut" + std::to_string(cut) + ".glb", good.substr(0, cut));
  TriangleMesh one;
  one.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  one.triangles = {{0, 1, 2}};
  EXPECT_FALSE(WriteMeshGlb(dir + "/x.glb",
                            [&] {
                              TriangleMesh m = one;
                              m.triangles[0][2] = 3;
                              return m;
                            }())
                   .ok());
  ASSERT_TRUE(WriteMeshGlb(dir + "/one.glb", one).ok());
  std::string bad_index;
  ASSERT_TRUE(ReadFileToString(dir + "/one.glb", &bad_index).ok());
  const size_t bin = bad_index.size() - 4;  // the last index is the file's last 4 bytes
  const uint32_t past = 3;
  std::memcpy(&bad_index[bin], &past, 4);
  cases.emplace_back("bad_index.glb", bad_index);
  for (const auto& [name, bytes] : cases) {
    ASSERT_TRUE(WriteStringToFileAtomic(dir + "/" + name, bytes).ok());
    const Status s = ReadMeshGlb(dir + "/" + name, &out);
    EXPECT_FALSE(s.ok()) << name;
    EXPECT_NE(s.message().find(name), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << s.message();
  }
}

// Seeded mutations (flipped bytes, 32-bit fields overwritten with extreme values, truncation) of a
// valid file: the reader either reads a mesh whose indices are in range or refuses with one line
// naming the file; never a crash or an out-of-bounds read (the sanitizer build runs this too).
TEST(MeshGlbTest, MutatedFilesAreReadOrRefusedCleanly) {
  const std::string dir = testing::ScratchDir();
  TriangleMesh small = MakeTorus(0.7, 0.25, 6, 4);
  small.vertex_colors.assign(small.vertices.size(), Eigen::Vector3f(0.2f, 0.5f, 0.9f));
  ASSERT_TRUE(WriteMeshGlb(dir + "/m.glb", small).ok());
  std::string good;
  ASSERT_TRUE(ReadFileToString(dir + "/m.glb", &good).ok());
  Rng rng(7);
  int refused = 0;
  const uint32_t extremes[] = {0u, 1u, 0x7fffffffu, 0xffffffffu, 0x80000000u, 4096u};
  for (int c = 0; c < 400; ++c) {
    std::string bytes = good;
    const int kind = static_cast<int>(rng.UniformInt(3));
    if (kind == 0) {
      for (int k = 0; k < 4; ++k)
        bytes[rng.UniformInt(bytes.size())] = static_cast<char>(rng.UniformInt(256));
    } else if (kind == 1) {
      const size_t at = rng.UniformInt(bytes.size() / 4) * 4;
      std::memcpy(&bytes[at], &extremes[rng.UniformInt(6)], 4);
    } else {
      bytes.resize(rng.UniformInt(bytes.size()));
    }
    const std::string path = dir + "/case.glb";
    ASSERT_TRUE(WriteStringToFileAtomic(path, bytes).ok());
    TriangleMesh out;
    const Status s = ReadMeshGlb(path, &out);
    if (s.ok()) {
      for (const Eigen::Vector3i& t : out.triangles)
        for (int k = 0; k < 3; ++k)
          ASSERT_TRUE(t[k] >= 0 && static_cast<size_t>(t[k]) < out.vertices.size()) << c;
      continue;
    }
    ++refused;
    EXPECT_NE(s.message().find(path), std::string::npos) << c << ": " << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << c << ": " << s.message();
  }
  EXPECT_GT(refused, 100);  // the mutations reach the error paths
}

// Open3D's Python package (Debian python3-open3d, what users script with) reads both files: the
// same counts, normals, and colours (linear in the .glb, as glTF defines them).
TEST(Open3DPythonInteropTest, ReadsOurMeshPlyAndGlb) {
  const std::string python = FindProgram("/usr/bin/python3");
  const std::string log0 = testing::ScratchDir() + "/probe.log";
  if (python.empty() || RunProgram({python, "-c", "import open3d"}, {}, log0, 60).exit_code != 0)
    GTEST_SKIP() << "Debian's python3-open3d is not installed (scripts/install_npm_tools.sh "
                    "installs it)";
  const std::string dir = testing::ScratchDir();
  const TriangleMesh mesh = ColouredTorus();
  ASSERT_TRUE(WriteMeshGlb(dir + "/m.glb", mesh).ok());
  ASSERT_TRUE(WriteTriangleMesh(dir + "/m.ply", mesh).ok());
  const ProgramResult r =
      RunProgram({python, std::string(MGSR_SOURCE_DIR) + "/tests/third_party/read_mesh_open3d.py",
                  dir + "/m.ply", dir + "/m.glb"},
                 {}, dir + "/open3d.log", 120);
  std::string log;
  EXPECT_TRUE(ReadFileToString(dir + "/open3d.log", &log).ok());
  ASSERT_TRUE(r.started && r.exit_code == 0) << log;
  double mean[3] = {0, 0, 0}, mean_linear[3] = {0, 0, 0}, min_x = 1e9, max_x = -1e9;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      mean[c] += mesh.vertex_colors[i][c] / mesh.vertices.size();
      mean_linear[c] += SrgbToLinear(mesh.vertex_colors[i][c]) / mesh.vertices.size();
    }
    min_x = std::min(min_x, mesh.vertices[i].x());
    max_x = std::max(max_x, mesh.vertices[i].x());
  }
  std::istringstream lines(log);
  int files = 0;
  for (std::string name; lines >> name;) {
    size_t vertices, triangles;
    int colors, normals;
    double got[3], lo, hi;
    lines >> vertices >> triangles >> colors >> normals >> got[0] >> got[1] >> got[2] >> lo >> hi;
    SCOPED_TRACE(name);
    ++files;
    EXPECT_EQ(vertices, mesh.vertices.size());
    EXPECT_EQ(triangles, mesh.triangles.size());
    EXPECT_EQ(colors, 1);
    EXPECT_EQ(normals, 1);
    const double* want = name == "m.glb" ? mean_linear : mean;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], want[c], 0.003);
    EXPECT_NEAR(lo, min_x, 1e-5);
    EXPECT_NEAR(hi, max_x, 1e-5);
  }
  EXPECT_EQ(files, 2) << log;
}

// ---- Against the Khronos glTF Validator (npm gltf-validator, pinned in tests/third_party;
// scripts/install_npm_tools.sh installs it under the build folder).
TEST(GltfValidatorInteropTest, OurGlbHasNoErrorsOrWarnings) {
  const std::string modules = std::string(MGSR_NPM_TOOLS_DIR) + "/node_modules";
  const std::string node = FindProgram("node");
  if (node.empty() || !FileExists(modules + "/gltf-validator/package.json"))
    GTEST_SKIP() << "gltf-validator is not installed under " MGSR_NPM_TOOLS_DIR
                    " (bash scripts/install_npm_tools.sh installs it; it needs node, npm and the "
                    "npm registry)";
  const std::string dir = testing::ScratchDir();
  // A mesh as TSDF fusion gives them: some vertices unused, a degenerate triangle.
  TriangleMesh mesh = ColouredTorus();
  mesh.vertices.emplace_back(5, 5, 5);
  mesh.vertex_colors.emplace_back(1, 1, 1);
  mesh.triangles.emplace_back(0, 0, 1);
  ASSERT_TRUE(WriteMeshGlb(dir + "/m.glb", mesh).ok());
  const ProgramResult r =
      RunProgram({node, std::string(MGSR_SOURCE_DIR) + "/tests/third_party/validate_gltf.js",
                  modules, dir + "/m.glb"},
                 {}, dir + "/validator.log", 120);
  std::string log;
  EXPECT_TRUE(ReadFileToString(dir + "/validator.log", &log).ok());
  EXPECT_TRUE(r.started && r.exit_code == 0) << log;
  EXPECT_NE(log.find("0 errors, 0 warnings"), std::string::npos) << log;
}

}  // namespace
}  // namespace mgsr
