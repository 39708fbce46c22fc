// Our 3DGS PLY in a real web splat viewer: Spark (@sparkjsdev/spark on three.js, npm, pinned in
// tests/third_party) renders it in headless Chromium (Debian's chromium, software WebGL), and its
// frame must match our own render of the same camera. A disagreement in SH order or signs,
// activations, quaternion order, axes or the camera model shows as a low PSNR.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>

#include "mgsr/core/camera.h"
#include "mgsr/core/rng.h"
#include "mgsr/core/subprocess.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/render/gaussian_renderer.h"
#include "mgsr/synth/shapes.h"
#include "test_util.h"

namespace mgsr {
namespace {

// Splats over a torus as a trained object has them: flattened along random axes, mostly opaque,
// a colour that varies over the surface and view-dependent SH of degree 3.
GaussianModel TorusOfSplats() {
  const TriangleMesh torus = MakeTorus(0.7, 0.28, 64, 24);
  Rng rng(11);
  GaussianModel m;
  m.max_sh_degree = 3;
  m.Resize(torus.vertices.size());
  const int K = m.sh_coeffs();
  for (size_t i = 0; i < m.size(); ++i) {
    const Eigen::Vector3d& p = torus.vertices[i];
    for (int d = 0; d < 3; ++d) m.means[i * 3 + d] = static_cast<float>(p[d]);
    m.log_scales[i * 3 + 0] = std::log(rng.Uniform(0.03f, 0.06f));
    m.log_scales[i * 3 + 1] = std::log(rng.Uniform(0.03f, 0.06f));
    m.log_scales[i * 3 + 2] = std::log(0.008f);
    for (int d = 0; d < 4; ++d) m.quats[i * 4 + d] = rng.Uniform(-1.0f, 1.0f);
    m.opacity_logits[i] = rng.Uniform(0.0f, 4.0f);
    const float dc[3] = {static_cast<float>(p.x()), static_cast<float>(p.y()),
                         static_cast<float>(p.z() * 2.0)};
    for (int c = 0; c < 3; ++c) {
      m.sh[(i * K) * 3 + c] = 0.9f * dc[c];
      for (int k = 1; k < K; ++k) m.sh[(i * K + k) * 3 + c] = rng.Uniform(-0.25f, 0.25f);
    }
  }
  return m;
}

std::string Chromium() {
  if (const char* env = std::getenv("MGSR_CHROMIUM")) return FindProgram(env);
  for (const char* name : {"chromium", "chromium-browser", "google-chrome"}) {
    const std::string path = FindProgram(name);
    if (!path.empty()) return path;
  }
  return "";
}

TEST(SparkViewerInteropTest, ItsFrameOfOurPlyMatchesOurRender) {
  const std::string modules = std::string(MGSR_NPM_TOOLS_DIR) + "/node_modules";
  const std::string node = FindProgram("node");
  const std::string chromium = Chromium();
  if (node.empty() || !FileExists(modules + "/@sparkjsdev/spark/package.json"))
    GTEST_SKIP() << "Spark is not installed under " MGSR_NPM_TOOLS_DIR
                    " (bash scripts/install_npm_tools.sh installs it; it needs node, npm and the "
                    "npm registry)";
  if (chromium.empty())
    GTEST_SKIP() << "no Chromium to run the web viewer in (Debian: apt-get install chromium; "
                    "scripts/install_deps.sh installs it)";
  const std::string dir = testing::ScratchDir();
  const GaussianModel model = TorusOfSplats();
  ASSERT_TRUE(WriteGaussianPly(dir + "/model.ply", model).ok());

  // A non-square image with an off-centre principal point, seen from above and to the side.
  Camera cam = LookAtCamera({0.9, -1.6, 2.0}, {0.05, 0.0, 0.0}, {0, 0, 1}, 200, 160, 190, 190);
  cam.cx += 6.5;
  cam.cy -= 4.0;
  const float background[3] = {0.1f, 0.15f, 0.2f};

  GaussianRenderOptions options;
  options.camera = cam;
  options.reflection = false;
  std::copy(background, background + 3, options.background);
  GaussianRenderer renderer;
  GaussianRender ours;
  renderer.Forward(model, options, &ours);
  ASSERT_TRUE(WriteImage(dir + "/ours.png", ours.color).ok());

  // three.js camera-to-world: ours (x right, y down, z forward) turned to x right, y up, z back.
  Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
  c2w.block<3, 3>(0, 0) = cam.R.transpose() * Eigen::Vector3d(1, -1, -1).asDiagonal();
  c2w.block<3, 1>(0, 3) = cam.Center();
  nlohmann::json c2w_json = nlohmann::json::array();
  for (int col = 0; col < 4; ++col)
    for (int row = 0; row < 4; ++row) c2w_json.push_back(c2w(row, col));
  const nlohmann::json camera = {{"width", cam.width},
                                 {"height", cam.height},
                                 {"fx", cam.fx},
                                 {"fy", cam.fy},
                                 {"cx", cam.cx},
                                 {"cy", cam.cy},
                                 {"near", 0.05},
                                 {"far", 50.0},
                                 {"camera_to_world", c2w_json},
                                 {"background", {background[0], background[1], background[2]}},
                                 {"frames", 40}};
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/camera.json", camera.dump()).ok());

  const ProgramResult r = RunProgram(
      {node, std::string(MGSR_SOURCE_DIR) + "/tests/third_party/spark_viewer/render.js", modules,
       chromium, dir + "/model.ply", dir + "/camera.json", dir + "/spark.png", "150"},
      {}, dir + "/viewer.log", 200);
  std::string log;
  EXPECT_TRUE(ReadFileToString(dir + "/viewer.log", &log).ok());
  ASSERT_TRUE(r.started && r.exit_code == 0) << log;
  Image theirs;
  ASSERT_TRUE(ReadImage(dir + "/spark.png", &theirs).ok());
  ASSERT_EQ(theirs.width(), cam.width);
  ASSERT_EQ(theirs.height(), cam.height);
  ASSERT_GE(theirs.channels(), 3);
  Image theirs_rgb(cam.width, cam.height, 3);  // the canvas is RGBA, opaque
  std::copy(theirs.plane(0), theirs.plane(0) + theirs_rgb.size(), theirs_rgb.data());
  Image ours_png;  // ours through the same 8-bit quantisation
  ASSERT_TRUE(ReadImage(dir + "/ours.png", &ours_png).ok());
  const double psnr = Psnr(ours_png, theirs_rgb);
  std::printf("Spark's frame against our render: PSNR %.2f dB (%s)\n", psnr, dir.c_str());
  EXPECT_GT(psnr, 40.0) << "compare " << dir << "/ours.png with " << dir << "/spark.png\n" << log;
}

}  // namespace
}  // namespace mgsr
