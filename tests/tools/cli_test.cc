// The CLIs: success paths, and every bad-input case gives a one-line error naming the file and a
// non-zero exit status (never a crash).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <tuple>

#include "mgsr/core/subprocess.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/mesh_glb.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/io/output_folder.h"
#include "mgsr/io/ply.h"
#include "mgsr/io/splat_formats.h"
#include "solvers/solver_options.h"
#include "test_util.h"

namespace mgsr {
namespace {

namespace fs = std::filesystem;

const std::string kTools = MGSR_TOOLS_DIR;

class CliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    base_ =
        (fs::path(::testing::TempDir()) / "mgsr_tests" / ("cli_base_" + std::to_string(getpid())))
            .string();
    fs::remove_all(base_);
    const auto r = testing::RunCommand(kTools + "/mgsr_synth --output " + base_ +
                                       " --num_views 10 --width 32 --height 32 --num_points 100");
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  // A private copy of the base scene to break.
  std::string Copy() {
    const std::string dir = testing::ScratchDir();
    fs::remove_all(dir);
    fs::copy(base_, dir, fs::copy_options::recursive);
    return dir;
  }
  void ExpectSolveFails(const std::string& dir, const std::string& expected) {
    const auto r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " +
                                       dir + "/out");
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_EQ(r.output.rfind("error: ", 0), 0u) << r.output;
    EXPECT_NE(r.output.find(expected), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << "one line: " << r.output;
  }
  void EditModel(const std::string& dir, void (*edit)(ColmapModel*)) {
    ColmapModel m;
    ASSERT_TRUE(ReadColmapModel(dir + "/sparse/0", &m).ok());
    edit(&m);
    ASSERT_TRUE(WriteColmapModel(dir + "/sparse/0", m, ColmapFormat::kBinary).ok());
  }
  static std::string base_;
};
std::string CliTest::base_;

// The tools' OpenMP threads spin only briefly while they wait, unless the user chose a policy
// (a spinning thread slows the working one on a machine where another process holds a core).
TEST_F(CliTest, ToolsSpinBrieflyUnlessTheUserChose) {
  for (const std::string policy : {"", "ACTIVE"}) {
    const std::string out = Copy() + "/out";
    const auto r = testing::RunCommand(
        (policy.empty() ? "env -u OMP_WAIT_POLICY -u GOMP_SPINCOUNT -u MGSR_OPENMP_WAIT_SET "
                        : "env -u GOMP_SPINCOUNT OMP_WAIT_POLICY=" + policy + " ") +
        kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
        " --warmup_max_iterations 4 --warmup_min_iterations 0 --mutual_iterations 2");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    std::string text;
    ASSERT_TRUE(ReadFileToString(out + "/metrics.json", &text).ok());
    const nlohmann::json m = nlohmann::json::parse(text);
    EXPECT_EQ(m["threads"]["omp_wait_policy"], policy);
    EXPECT_EQ(m["threads"]["gomp_spincount"], policy.empty() ? "300" : "");
  }
}

// RGB photos with separate masks are scored on the object: the test views' truth is the photo
// composited through its mask on the branch's background, not the photo's own backdrop.
TEST_F(CliTest, RgbPhotosWithMasksAreScoredOnTheObject) {
  const std::string dir = Copy();
  // The photos as a camera takes them: the object before a magenta wall, no alpha.
  for (const auto& entry : fs::directory_iterator(dir + "/images")) {
    Image rgba;
    ASSERT_TRUE(ReadImage(entry.path().string(), &rgba).ok());
    Image rgb(rgba.width(), rgba.height(), 3);
    const float wall[3] = {1.0f, 0.0f, 1.0f};
    for (int c = 0; c < 3; ++c)
      for (size_t i = 0; i < rgb.plane_size(); ++i)
        rgb.plane(c)[i] = rgba.plane(c)[i] * rgba.plane(3)[i] + wall[c] * (1 - rgba.plane(3)[i]);
    ASSERT_TRUE(WriteImage(entry.path().string(), rgb).ok());
  }
  const std::string out = dir + "/out";
  const auto r =
      testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " + out +
                          " --background 0.25 --warmup_max_iterations 4 "
                          "--warmup_min_iterations 0 --mutual_iterations 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  Image truth, mask;
  ASSERT_TRUE(ReadImage(out + "/renders/v000_gt.png", &truth).ok());
  ASSERT_TRUE(ReadImage(dir + "/masks/v000.png", &mask).ok());
  int background = 0;
  for (size_t i = 0; i < mask.plane_size(); ++i) {
    if (mask.plane(0)[i] > 0.01f) continue;
    ++background;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(truth.plane(c)[i], 0.25f, 0.01f);
  }
  EXPECT_GT(background, 100);
  std::string text;
  ASSERT_TRUE(ReadFileToString(out + "/metrics.json", &text).ok());
  const nlohmann::json m = nlohmann::json::parse(text);
  EXPECT_TRUE(m["test"].contains("psnr_foreground")) << m["test"].dump();
}

// Views longer than --coarse_max_size train the first part of each stage downscaled (with two
// levels a quarter of the fit, then the fit): the log says so and metrics.json records the
// factors and where each stage switched; a negative size and no levels are refused.
TEST_F(CliTest, SolveWithACoarseStartSaysSoAndRecordsIt) {
  const std::string out = Copy() + "/out";
  const auto r =
      testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
                          " --warmup_max_iterations 20 --warmup_min_iterations 0 "
                          "--mutual_iterations 6 --coarse_max_size 16 --coarse_levels 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("coarse start: the first 75% of each stage at 1/4 size (8x8), then 1/2 "
                          "size (16x16), then 32x32"),
            std::string::npos)
      << r.output;
  std::string text;
  ASSERT_TRUE(ReadFileToString(out + "/metrics.json", &text).ok());
  const nlohmann::json m = nlohmann::json::parse(text);
  EXPECT_EQ(m["coarse"]["factor"], 2);
  EXPECT_EQ(m["coarse"]["levels"], 2);
  EXPECT_EQ(m["coarse"]["factors"], nlohmann::json::parse("[4, 2]"));
  EXPECT_EQ(m["coarse"]["warmup_iterations"], 15);
  EXPECT_EQ(m["coarse"]["mutual_iterations"], 4);
  // One level (the default): half size, then full size.
  const auto one = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " +
                                       out + "_one --coarse_max_size 16 --check");
  ASSERT_EQ(one.exit_code, 0) << one.output;
  EXPECT_NE(one.output.find("coarse start: the first 75% of each stage at 1/2 size (16x16), then "
                            "32x32"),
            std::string::npos)
      << one.output;
  const auto full = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " +
                                        out + "_full --check");
  ASSERT_EQ(full.exit_code, 0) << full.output;
  EXPECT_EQ(full.output.find("coarse start"), std::string::npos) << full.output;
  const auto bad = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " +
                                       out + "_bad --coarse_max_size -1");
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("--coarse_max_size must be >= 0"), std::string::npos) << bad.output;
  const auto no_levels =
      testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
                          "_bad_levels --coarse_max_size 16 --coarse_levels 0");
  EXPECT_EQ(no_levels.exit_code, 1) << no_levels.output;
  EXPECT_NE(no_levels.output.find("--coarse_levels must be in [1, 8]"), std::string::npos)
      << no_levels.output;
}

TEST_F(CliTest, SolveReconstructsAGoodSceneAndWritesItsOutputs) {
  const std::string out = Copy() + "/out";
  const auto r =
      testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
                          " --warmup_max_iterations 40 --warmup_min_iterations 0 "
                          "--mutual_iterations 10 --log_every 20");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("8 train / 2 test views, 32x32, 100 points, masks: yes"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("test views: PSNR"), std::string::npos) << r.output;
  for (const char* f : {"metrics.json", "log.csv", "point_cloud_2d.ply", "point_cloud_3d.ply",
                        "mesh.ply", "renders/v000_composite.png", "renders/v000_depth2d.png",
                        "renders/v000_depth2d_error.png"}) {  // the scene has gt/depth
    EXPECT_TRUE(FileExists(out + "/" + f)) << f;
  }
  // The depth picture is readable: colour-mapped over the object's own depth range, so the
  // object's pixels are bright and several colours, not a near-black grey ramp.
  Image depth_png;
  ASSERT_TRUE(ReadImage(out + "/renders/v000_depth2d.png", &depth_png).ok());
  ASSERT_EQ(depth_png.channels(), 3);
  double brightest = 0, red = 0, blue = 0;
  for (int y = 0; y < depth_png.height(); ++y) {
    for (int x = 0; x < depth_png.width(); ++x) {
      const float r = depth_png.at(0, y, x), g = depth_png.at(1, y, x), b = depth_png.at(2, y, x);
      brightest = std::max<double>(brightest, std::max({r, g, b}));
      red = std::max<double>(red, r - b);
      blue = std::max<double>(blue, b - r);
    }
  }
  EXPECT_GT(brightest, 0.8);
  EXPECT_GT(red, 0.3);   // near parts
  EXPECT_GT(blue, 0.3);  // far parts
  std::string metrics;
  ASSERT_TRUE(ReadFileToString(out + "/metrics.json", &metrics).ok());
  EXPECT_NE(metrics.find("\"psnr\""), std::string::npos);
  EXPECT_NE(metrics.find("\"psnr_aligned\""), std::string::npos);
  EXPECT_NE(metrics.find("\"nc\""),
            std::string::npos);  // the synthetic scene has a ground-truth mesh
  // By default the MCMC strategy with --budget auto: each branch's budget from the object's size
  // in pixels, the same rule for both (135 surfels for every 180 Gaussians).
  EXPECT_NE(r.output.find("(auto: "), std::string::npos) << r.output;
  const nlohmann::json parsed = nlohmann::json::parse(metrics);
  EXPECT_EQ(parsed["budget"]["mode"], "auto");
  EXPECT_EQ(parsed["budget"]["density"], "mcmc");
  const int64_t gaussians = parsed["budget"]["gaussians"], surfels = parsed["budget"]["surfels"];
  EXPECT_GT(gaussians, 0);
  EXPECT_NEAR(static_cast<double>(surfels) / gaussians, 135.0 / 180.0, 0.01);
  // mgsr_eval scores the run folder: NC, CD, PSNR, SSIM, time.
  const auto e =
      testing::RunCommand(kTools + "/mgsr_eval --run " + out + " --json " + out + "/eval.json");
  ASSERT_EQ(e.exit_code, 0) << e.output;
  EXPECT_NE(e.output.find("NC x100"), std::string::npos) << e.output;
  ASSERT_TRUE(ReadFileToString(out + "/eval.json", &metrics).ok());
  EXPECT_NE(metrics.find("\"cd\""), std::string::npos);
  const auto bad = testing::RunCommand(kTools + "/mgsr_eval --run " + base_);
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("metrics.json: cannot open"), std::string::npos) << bad.output;

  // mgsr_render: the test views again, as mgsr_solve rendered them, and an orbit.
  auto rr = testing::RunCommand(kTools + "/mgsr_render --run " + out + " --output " + out +
                                "/again --views test");
  ASSERT_EQ(rr.exit_code, 0) << rr.output;
  for (const char* view : {"v000", "v008"}) {
    Image ours, solved;
    ASSERT_TRUE(ReadImage(out + "/again/" + view + "_composite.png", &ours).ok()) << rr.output;
    ASSERT_TRUE(ReadImage(out + "/renders/" + view + "_composite.png", &solved).ok());
    EXPECT_GT(Psnr(ours, solved), 45) << view;
  }
  rr = testing::RunCommand(kTools + "/mgsr_render --run " + out + " --output " + out +
                           "/orbit --orbit 4 --width 48 --sheet 2");
  ASSERT_EQ(rr.exit_code, 0) << rr.output;
  Image sheet;
  ASSERT_TRUE(ReadImage(out + "/orbit/sheet.png", &sheet).ok());
  EXPECT_EQ(sheet.width(), 2 * 48 + 2);  // two cameras, composite / depth / normal rows
  EXPECT_EQ(sheet.height(), 3 * 48 + 2 * 2);
  for (int i = 0; i < 4; ++i) {
    for (const char* what : {"composite", "transmitted", "reflected", "depth", "normal"}) {
      Image im;
      const std::string f = out + "/orbit/000" + std::to_string(i) + "_" + what + ".png";
      ASSERT_TRUE(ReadImage(f, &im).ok()) << f;
      EXPECT_EQ(im.width(), 48);
      if (std::string(what) == "depth") {
        // The object fills part of the frame: some pixels coloured, the background black.
        int coloured = 0;
        for (size_t k = 0; k < im.plane_size(); ++k)
          coloured += im.plane(0)[k] + im.plane(2)[k] > 0;
        EXPECT_GT(coloured, 48 * 48 / 20) << f;
        EXPECT_LT(coloured, 48 * 48) << f;
      }
    }
  }
  // The orbit as a video when ffmpeg is installed (scripts/install_npm_tools.sh installs it for
  // the tests); without it the tool says so.
  if (FindProgram("ffmpeg").empty() || FindProgram("ffprobe").empty()) {
    EXPECT_NE(rr.output.find("ffmpeg is not on the PATH"), std::string::npos) << rr.output;
  } else {
    EXPECT_NE(rr.output.find("video: " + out + "/orbit/orbit.mp4"), std::string::npos) << rr.output;
    const auto probe =
        testing::RunCommand(FindProgram("ffprobe") +
                            " -v error -count_frames -select_streams v:0 -show_entries "
                            "stream=nb_read_frames,width,height -of csv=p=0 " +
                            out + "/orbit/orbit.mp4");
    EXPECT_EQ(probe.output, "48,48,4\n");  // width, height, frames
    EXPECT_FALSE(FileExists(out + "/orbit/orbit.partial.mp4"));
  }
  rr = testing::RunCommand(kTools + "/mgsr_render --run " + base_ + " --output " + out + "/x");
  EXPECT_EQ(rr.exit_code, 1);
  EXPECT_NE(rr.output.find("metrics.json: cannot open"), std::string::npos) << rr.output;
  EXPECT_EQ(std::count(rr.output.begin(), rr.output.end(), '\n'), 1) << rr.output;
}

// #23: a scene-level run learns its background; the run keeps the map (environment_*.pfm, listed
// in metrics.json) and mgsr_render draws it behind new views as mgsr_solve did.
TEST_F(CliTest, LearntBackgroundIsWrittenAndRenderedAgain) {
  const std::string dir = testing::ScratchDir();
  fs::remove_all(dir);
  auto r = testing::RunCommand(kTools + "/mgsr_synth --output " + dir +
                               "/scene --scene_type outdoor --num_views 10 --width 40 --height 30 "
                               "--num_points 300");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + "/scene --output " + dir +
                          "/out --warmup_max_iterations 30 --warmup_min_iterations 0 "
                          "--mutual_iterations 10 --log_every 100 --eval_every 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("background: learnt per viewing direction"), std::string::npos)
      << r.output;
  std::string text;
  ASSERT_TRUE(ReadFileToString(dir + "/out/metrics.json", &text).ok());
  const nlohmann::json metrics = nlohmann::json::parse(text);
  // A scene in the world trains without depth TVs (ReconstructionOptions::depth_tv_from_scene).
  EXPECT_NE(r.output.find("depth TVs: off (a scene in the world"), std::string::npos) << r.output;
  int depth_tv_rows = 0;
  for (const auto& row : metrics["losses"]) {
    if (row.value("name", std::string()) != "depth_tv") continue;
    ++depth_tv_rows;
    EXPECT_EQ(row.value("weight", -1.0), 0.0) << row.dump();
  }
  EXPECT_EQ(depth_tv_rows, 3);
  EXPECT_TRUE(VerifyOutputManifest(dir + "/out", metrics).ok());
  for (const char* branch : {"2d", "3d"}) {
    const std::string name = std::string("environment_") + branch + ".pfm";
    EXPECT_EQ(metrics["background"]["environment"][branch], name);
    Image map;
    ASSERT_TRUE(ReadPfm(dir + "/out/" + name, &map).ok()) << name;
    EXPECT_EQ(map.width(), 64);
    EXPECT_EQ(map.height(), 32);
    EXPECT_EQ(map.channels(), 3);
  }
  r = testing::RunCommand(kTools + "/mgsr_render --run " + dir + "/out --output " + dir +
                          "/again --views test");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  Image ours, solved, on_grey;
  ASSERT_TRUE(ReadImage(dir + "/again/v000_composite.png", &ours).ok()) << r.output;
  ASSERT_TRUE(ReadImage(dir + "/out/renders/v000_composite.png", &solved).ok());
  EXPECT_GT(Psnr(ours, solved), 45);
  // Without the maps the sky is the flat background: clearly another image.
  fs::remove(dir + "/out/environment_2d.pfm");
  fs::remove(dir + "/out/environment_3d.pfm");
  r = testing::RunCommand(kTools + "/mgsr_render --run " + dir + "/out --output " + dir +
                          "/grey --views test");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(ReadImage(dir + "/grey/v000_composite.png", &on_grey).ok());
  EXPECT_LT(Psnr(on_grey, solved), 35);
}

// #18: one run's results are never mixed with another's, and metrics.json vouches for each file.
TEST_F(CliTest, SolveRefusesAStaleFolderAndListsWhatItWrote) {
  const std::string dir = Copy();
  const std::string solve = kTools + "/mgsr_solve --workspace " + base_ +
                            " --warmup_max_iterations 10 --warmup_min_iterations 0 "
                            "--mutual_iterations 4 --log_every 100 --eval_every 0 --output ";
  auto r = testing::RunCommand(solve + dir + "/a");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = testing::RunCommand(solve + dir + "/b --seed 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = testing::RunCommand(solve + dir + "/a --seed 3");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output, "error: " + dir +
                          "/a: output folder is not empty (use --overwrite to "
                          "replace a previous run, or --resume to continue it)\n");
  r = testing::RunCommand(solve + dir + "/a --resume --overwrite");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.output, "error: --resume and --overwrite exclude each other\n");

  // Every result is listed with its size and SHA-256, and the list is complete.
  std::string text;
  ASSERT_TRUE(ReadFileToString(dir + "/a/metrics.json", &text).ok());
  const nlohmann::json metrics = nlohmann::json::parse(text);
  ASSERT_TRUE(metrics.contains("files"));
  EXPECT_TRUE(VerifyOutputManifest(dir + "/a", metrics).ok());
  size_t renders = 0;
  for (const auto& e : fs::directory_iterator(dir + "/a/renders")) {
    EXPECT_TRUE(metrics["files"].contains("renders/" + e.path().filename().string())) << e.path();
    ++renders;
  }
  EXPECT_EQ(renders, 2u * 8u);  // two test views, eight images each (with the depth error)
  for (const char* f : {"mesh.ply", "point_cloud_2d.ply", "point_cloud_3d.ply"})
    EXPECT_TRUE(metrics["files"].contains(f)) << f;

  // Another run's mesh beside these metrics is caught by mgsr_eval --run.
  fs::copy_file(dir + "/b/mesh.ply", dir + "/a/mesh.ply", fs::copy_options::overwrite_existing);
  r = testing::RunCommand(kTools + "/mgsr_eval --run " + dir + "/a");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output.rfind("error: " + dir + "/a/mesh.ply: does not match the checksum in", 0), 0u)
      << r.output;

  // --overwrite replaces the run: nothing of the old one survives beside the new one.
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/a/renders/stale_gt.png", "x").ok());
  r = testing::RunCommand(solve + dir + "/a --overwrite --seed 3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/a/renders/stale_gt.png"));
  ASSERT_TRUE(ReadFileToString(dir + "/a/metrics.json", &text).ok());
  EXPECT_TRUE(VerifyOutputManifest(dir + "/a", nlohmann::json::parse(text)).ok());
  r = testing::RunCommand(kTools + "/mgsr_eval --run " + dir + "/a");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

// A run that cannot write its results fails, and takes back what it wrote: a file-size limit
// stands in for a full disk (the writes fail with EFBIG once SIGXFSZ is ignored).
TEST_F(CliTest, SolveThatCannotWriteLeavesNoResult) {
  const std::string dir = Copy();
  const std::string args = " --workspace " + base_ +
                           " --warmup_max_iterations 10 --warmup_min_iterations 0 "
                           "--mutual_iterations 4 --log_every 100 --eval_every 0 "
                           "--checkpoint_every 0 --surfel_spread off --output " +
                           dir + "/full";
  // 80 kB: the models (26 and 48 kB) and renders are written, the mesh (~100 kB) is not.
  auto r = testing::RunCommand("bash -c \"trap '' XFSZ; ulimit -f 80; " + kTools + "/mgsr_solve" +
                               args + "\"");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find(dir + "/full/mesh.ply: write failed (disk full?)"), std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("error: "), r.output.rfind("error: ")) << "one error: " << r.output;
  for (const char* f :
       {"metrics.json", "mesh.ply", "point_cloud_2d.ply", "point_cloud_3d.ply", "renders"}) {
    EXPECT_FALSE(fs::exists(dir + "/full/" + f)) << f;
  }
  // An output below a file cannot be created: refused before any training.
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/plain_file", "x").ok());
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/plain_file/out");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output.rfind("error: " + dir + "/plain_file/out: cannot create folder", 0), 0u)
      << r.output;
}

// Ctrl-C once training is over (while models, renders and the mesh are written): whenever it
// lands, the folder ends either finished (exit 0, metrics.json vouching for every file) or with no
// result at all (exit 130, the finished state checkpointed), and --resume then writes the outputs.
TEST_F(CliTest, CtrlCWhileWritingTheOutputsLeavesNoHalfResult) {
  const std::string dir = Copy();
  int interrupted = 0;
  for (const char* delay : {"0", "0.02", "0.1", "0.3"}) {
    const std::string out = dir + "/out_" + delay;
    const std::string script =
        kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
        " --warmup_max_iterations 6 --warmup_min_iterations 0 --mutual_iterations 2 "
        "--log_every 100 --eval_every 0 --checkpoint_every 0 > " +
        out +
        ".log 2>&1 & pid=\\$!; "
        "until grep -q 'mutual: ' " +
        out +
        ".log 2>/dev/null || ! kill -0 \\$pid 2>/dev/null; "
        "do sleep 0.005; done; sleep " +
        delay +
        "; kill -INT \\$pid 2>/dev/null; wait \\$pid; "
        "echo exit=\\$?";
    const auto r = testing::RunCommand("bash -c \"" + script + "\"");
    std::string log;
    ASSERT_TRUE(ReadFileToString(out + ".log", &log).ok());
    if (r.output.find("exit=130") != std::string::npos) {
      ++interrupted;
      EXPECT_NE(log.find("interrupted while writing the outputs"), std::string::npos) << log;
      for (const char* f :
           {"metrics.json", "mesh.ply", "point_cloud_2d.ply", "point_cloud_3d.ply", "renders"}) {
        EXPECT_FALSE(fs::exists(out + "/" + f)) << delay << ": " << f;
      }
      const auto resumed = testing::RunCommand(
          kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
          " --warmup_max_iterations 6 --warmup_min_iterations 0 --mutual_iterations 2 "
          "--log_every 100 --eval_every 0 --checkpoint_every 0 --resume");
      ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
    } else {
      ASSERT_NE(r.output.find("exit=0"), std::string::npos) << r.output << log;
    }
    std::string text;
    ASSERT_TRUE(ReadFileToString(out + "/metrics.json", &text).ok()) << delay;
    EXPECT_TRUE(VerifyOutputManifest(out, nlohmann::json::parse(text)).ok()) << delay;
  }
  EXPECT_GE(interrupted, 1) << "no signal landed while the outputs were written";
}

// --check loads and validates without training or writing anything.
TEST_F(CliTest, CheckLoadsTheSceneAndWritesNothing) {
  const std::string dir = Copy();
  auto r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --check");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("check: the scene can be trained"), std::string::npos) << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --check --output " + dir +
                          "/out");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/out"));
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/split.txt", "# none\n").ok());
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --check");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output.rfind("error: " + dir + "/split.txt: lists no test views", 0), 0u) << r.output;
}

TEST_F(CliTest, SingleBranchMethodReportsAndWritesOnlyItsBranch) {
  const std::string out = Copy() + "/out";
  const auto r =
      testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
                          " --method 2dgs --warmup_max_iterations 30 "
                          "--warmup_min_iterations 0 --mutual_iterations 10 "
                          "--log_every 20");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Progress lines follow the 2DGS steps; the untrained 3DGS branch shows as "-".
  const size_t loss_2d = r.output.find("loss 2DGS ");
  ASSERT_NE(loss_2d, std::string::npos) << r.output;
  EXPECT_TRUE(std::isdigit(static_cast<unsigned char>(r.output[loss_2d + 10]))) << r.output;
  EXPECT_NE(r.output.find("3DGS - | surfels"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Gaussians - |"), std::string::npos) << r.output;
  EXPECT_TRUE(FileExists(out + "/point_cloud_2d.ply"));
  EXPECT_FALSE(FileExists(out + "/point_cloud_3d.ply"));
  EXPECT_TRUE(FileExists(out + "/mesh.ply"));
}

TEST_F(CliTest, SolveResumesFromItsCheckpointToTheSameResult) {
  const std::string dir = Copy();
  const std::string common = kTools + "/mgsr_solve --workspace " + base_ +
                             " --warmup_max_iterations 30 --warmup_min_iterations 0 "
                             "--mutual_iterations 12 --log_every 100";
  auto r = testing::RunCommand(common + " --output " + dir + "/a");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // A run that leaves a checkpoint every 7 iterations, then a resume from the last one.
  r = testing::RunCommand(common + " --output " + dir + "/b --checkpoint_every 7");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(FileExists(dir + "/b/checkpoints/latest.ckpt"));
  r = testing::RunCommand(common + " --output " + dir + "/b --resume");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("resuming from"), std::string::npos) << r.output;
  for (const char* f : {"point_cloud_2d.ply", "point_cloud_3d.ply"}) {
    std::string a, b;
    ASSERT_TRUE(ReadFileToString(dir + "/a/" + f, &a).ok());
    ASSERT_TRUE(ReadFileToString(dir + "/b/" + f, &b).ok());
    EXPECT_TRUE(a == b) << f << " differs after resuming";
  }
  // Resuming a finished run rebuilds its outputs: here with the model in every export format.
  r = testing::RunCommand(common + " --output " + dir + "/b --resume --export ply,splat,spz,glb");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  GaussianModel ply, splat, spz;
  ASSERT_TRUE(ReadGaussianPly(dir + "/b/point_cloud_3d.ply", &ply).ok());
  ASSERT_TRUE(ReadSplatFile(dir + "/b/point_cloud_3d.splat", &splat).ok());
  ASSERT_TRUE(ReadSpzFile(dir + "/b/point_cloud_3d.spz", &spz).ok());
  EXPECT_GT(ply.size(), 0u);
  EXPECT_EQ(splat.size(), ply.size());
  EXPECT_EQ(spz.size(), ply.size());
  TriangleMesh mesh_ply, mesh_glb;
  ASSERT_TRUE(ReadTriangleMesh(dir + "/b/mesh.ply", &mesh_ply).ok());
  ASSERT_TRUE(ReadMeshGlb(dir + "/b/mesh.glb", &mesh_glb).ok());
  EXPECT_EQ(mesh_glb.vertices.size(), mesh_ply.vertices.size());
  EXPECT_EQ(mesh_glb.triangles, mesh_ply.triangles);
  std::string metrics;
  ASSERT_TRUE(ReadFileToString(dir + "/b/metrics.json", &metrics).ok());
  EXPECT_NE(metrics.find("\"mesh.glb\""), std::string::npos) << "not in the manifest";
  // A run without glb removes the previous run's mesh.glb and splat files (they are results).
  r = testing::RunCommand(common + " --output " + dir + "/b --resume");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* f : {"mesh.glb", "point_cloud_3d.splat", "point_cloud_3d.spz"})
    EXPECT_FALSE(FileExists(dir + "/b/" + f)) << f << " of the previous run is still there";
  r = testing::RunCommand(common + " --output " + dir + "/c --resume");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("no checkpoint to resume from"), std::string::npos) << r.output;
}

TEST_F(CliTest, SolveRejectsBadOptions) {
  auto r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--output is required"), std::string::npos);
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --preset slow");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output, "error: unknown --preset 'slow' (fast or paper)\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --mutual_mode both");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--mutual_mode must be alternate or joint"), std::string::npos)
      << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --surfel_low_pass mip");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output, "error: --surfel_low_pass must be area or reference\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --surfel_filter_sigma 0");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--surfel_filter_sigma must be in [0.01, 2] pixels"), std::string::npos)
      << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --surfel_init pca");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output, "error: --surfel_init must be neighbours or random\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --lambda_distortion nan");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --lambda_distortion must be >= 0 (or -1 for the default)\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --lambda_normal -2");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --lambda_normal must be >= 0 (or -1 for the default)\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --export ply,obj");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --export: unknown format 'obj' (ply, splat, spz, glb)\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --budget lots");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --budget must be auto, scene, none or a count, not 'lots'\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --density mcmc --budget none");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--density: density strategy \"mcmc\": needs a budget"),
            std::string::npos)
      << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --density mcmc --density_config '{\"noise\": 1}'");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("unknown key \"noise\""), std::string::npos) << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --density_config '{oops'");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--density_config is not valid JSON"), std::string::npos) << r.output;
  for (const char* bad : {"1.5", "grey", "0.5x"}) {
    r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                            " --output /tmp/x --background " + bad);
    EXPECT_EQ(r.exit_code, 1) << bad;
    EXPECT_NE(
        r.output.find("--background must be auto, reference, env or a grey level in [0, 1], not '" +
                      std::string(bad) + "'"),
        std::string::npos)
        << r.output;
  }
  // Out of range: only -1 means "the preset's"; a batch larger than the training views; an
  // infinite far sphere; a render wider than any buffer should be.
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --mutual_iterations -5");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --mutual_iterations must be >= 0 (or -1 for the preset's)\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --position_lr_max_steps 0");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --position_lr_max_steps must be >= 1 (or -1 for the preset's)\n");
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ +
                          " --output /tmp/x --far_radius inf");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --far_radius must be in (1, 10000] scene extents\n");
  const std::string out = testing::ScratchDir() + "/out";
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + out +
                          " --batch_views 9");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("error: --batch_views 9 is more than the 8 training views of "),
            std::string::npos)
      << r.output;
  r = testing::RunCommand(kTools + "/mgsr_render --run " + base_ + " --output " + out +
                          "/render --orbit 2 --width 200000");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output, "error: --width must be in [1, 8192] (0: the training width)\n");
}

// Without test views there is no image score: metrics.json says why instead of a PSNR of 0, and
// names the workspace by its absolute path (mgsr_render --run works from any folder).
TEST_F(CliTest, NoTestViewsMeansNoPsnr) {
  const std::string dir = Copy();
  fs::remove(dir + "/split.txt");
  const std::string out = dir + "/out";
  const std::string rel = fs::relative(dir, fs::current_path()).string();
  const auto r =
      testing::RunCommand(kTools + "/mgsr_solve --workspace " + rel + " --output " + out +
                          " --test_every 0 --warmup_max_iterations 30 --warmup_min_iterations 20 "
                          "--mutual_iterations 10 --checkpoint_every 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("test views: none (--test_every 0 and no split file)"), std::string::npos)
      << r.output;
  std::string text;
  ASSERT_TRUE(ReadFileToString(out + "/metrics.json", &text).ok());
  const nlohmann::json m = nlohmann::json::parse(text);
  EXPECT_EQ(m["test"]["views"], 0);
  EXPECT_FALSE(m["test"].contains("psnr"));
  EXPECT_EQ(m["scene"], fs::absolute(dir).lexically_normal().string());
}

// Photos without masks on a uniform grey: --background auto renders both branches on that grey;
// with masks it keeps the reference's white/black.
TEST_F(CliTest, BackgroundAutoFollowsTheBackdropOfUnmaskedPhotos) {
  const std::string dir = testing::ScratchDir();
  fs::remove_all(dir);
  auto r = testing::RunCommand(kTools + "/mgsr_synth --output " + dir +
                               " --num_views 10 --width 32 --height 32 --num_points 100 "
                               "--masks=false");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string few =
      " --warmup_max_iterations 10 --warmup_min_iterations 0 "
      "--mutual_iterations 4 --log_every 20 --eval_every 0";
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " + dir + "/out" +
                          few);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("background: the photos' uniform backdrop, grey 0.6"), std::string::npos)
      << r.output;
  std::string metrics;
  ASSERT_TRUE(ReadFileToString(dir + "/out/metrics.json", &metrics).ok());
  EXPECT_NE(metrics.find("the photos' uniform backdrop"), std::string::npos) << metrics;
  // Without masks the normal weight is the reference's (a strong one grows backdrop sheets); the
  // loss table in metrics.json carries it.
  EXPECT_NE(r.output.find("normal weight: 0.05 (the reference's: no masks or alpha"),
            std::string::npos)
      << r.output;
  // The weight of the first row named `name` in `stage` (-1: none).
  auto row_weight = [](const std::string& json_text, const std::string& name,
                       const std::string& stage) {
    const nlohmann::json parsed = nlohmann::json::parse(json_text);
    for (const auto& row : parsed["losses"])
      if (row.value("name", std::string()) == name && row.value("stage", std::string()) == stage)
        return row.value("weight", -1.0);
    return -1.0;
  };
  auto normal_row_weight = [&](const std::string& json_text) {
    return row_weight(json_text, "normal_consistency", "warmup");
  };
  EXPECT_DOUBLE_EQ(normal_row_weight(metrics), 0.05) << metrics;
  // Without masks the depth distortion keeps the surfels in one layer: 1000, the mutual row
  // times w_2d (0.5).
  EXPECT_NE(r.output.find("depth distortion: 1000 (no masks or alpha"), std::string::npos)
      << r.output;
  EXPECT_DOUBLE_EQ(row_weight(metrics, "distortion", "warmup"), 1000.0) << metrics;
  EXPECT_DOUBLE_EQ(row_weight(metrics, "distortion", "mutual"), 500.0) << metrics;
  // An object before a uniform backdrop keeps the reference's depth TVs.
  EXPECT_EQ(r.output.find("depth TVs: off"), std::string::npos) << r.output;
  // Without masks one disk per initial point.
  EXPECT_EQ(r.output.find("initial disks:"), std::string::npos) << r.output;
  EXPECT_EQ(nlohmann::json::parse(metrics)["budget"]["spread_initial_surfels"], false) << metrics;
  // A loss configuration edits the table the scene chose: its row changes, the scene's normal
  // weight stays (it was once applied to the defaults' table, 2.0, before the scene was read).
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/l1.json",
                                      R"({"losses": [{"branch": "3d", "stage": "warmup", )"
                                      R"("name": "depth_tv", "weight": 0.125}]})")
                  .ok());
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " + dir +
                          "/out_config --loss_config " + dir + "/l1.json" + few);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(ReadFileToString(dir + "/out_config/metrics.json", &metrics).ok());
  EXPECT_DOUBLE_EQ(normal_row_weight(metrics), 0.05) << metrics;
  EXPECT_NE(metrics.find("0.125"), std::string::npos);
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/out_masked" + few);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("background: reference (2DGS white, 3DGS black): "), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("normal weight: 2 (the views have masks or alpha)"), std::string::npos)
      << r.output;
  ASSERT_TRUE(ReadFileToString(dir + "/out_masked/metrics.json", &metrics).ok());
  EXPECT_DOUBLE_EQ(normal_row_weight(metrics), 2.0);
  // With masks the distortion stays at the reference's 0.
  EXPECT_NE(r.output.find("depth distortion: 0 (the reference's: the views have masks or alpha)"),
            std::string::npos)
      << r.output;
  EXPECT_DOUBLE_EQ(row_weight(metrics, "distortion", "mutual"), 0.0) << metrics;
  // With masks the silhouette term is on in both stages (mutual: times w_2d, 0.5).
  EXPECT_NE(r.output.find("silhouette term: 3 in the warm-up, 3 in the mutual stage"),
            std::string::npos)
      << r.output;
  EXPECT_DOUBLE_EQ(row_weight(metrics, "mask", "warmup"), 3.0);
  EXPECT_DOUBLE_EQ(row_weight(metrics, "mask", "mutual"), 1.5);
  // With masks the initial points are spread to the 2DGS budget, and the layer prior is on.
  EXPECT_NE(r.output.find("initial disks: spread over the points' surfaces"), std::string::npos)
      << r.output;
  EXPECT_EQ(nlohmann::json::parse(metrics)["budget"]["spread_initial_surfels"], true) << metrics;
  EXPECT_DOUBLE_EQ(row_weight(metrics, "surfel_layer", "mutual"),
                   SolverOptions::kSurfelLayerWeightWithSpread);
  // A mutual stage no longer than fast's trains the 2DGS branch throughout.
  EXPECT_EQ(r.output.find("geometry:"), std::string::npos) << r.output;
  EXPECT_EQ(nlohmann::json::parse(metrics)["iterations"]["mutual_2d"], 4) << metrics;
  // A longer one, with masks, holds it after fast's 1,500; given, the flag decides, with or
  // without masks.
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/out_long --warmup_max_iterations 10 --warmup_min_iterations 0 "
                          "--mutual_iterations 1502 --log_every 2000 --eval_every 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("geometry: the 2DGS branch trains for the first 1500 of 1502 mutual "
                          "iterations, then is held"),
            std::string::npos)
      << r.output;
  ASSERT_TRUE(ReadFileToString(dir + "/out_long/metrics.json", &metrics).ok());
  EXPECT_EQ(nlohmann::json::parse(metrics)["iterations"]["mutual_2d"], 1500) << metrics;
  for (const std::string& workspace : {base_, dir}) {
    r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + workspace + " --output " + dir +
                            "/out_held --mutual_iterations_2d 2 --overwrite" + few);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(r.output.find("geometry:"), std::string::npos) << r.output;
    ASSERT_TRUE(ReadFileToString(dir + "/out_held/metrics.json", &metrics).ok());
    EXPECT_EQ(nlohmann::json::parse(metrics)["iterations"]["mutual_2d"], 2) << metrics;
  }
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/out_held_bad --mutual_iterations_2d -3" + few);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--mutual_iterations_2d must be >= 0 (or -1: the whole mutual stage)"),
            std::string::npos)
      << r.output;
  // A weight given for the term holds in both stages; the warm-up's can be given apart.
  for (const auto& [flag, warmup, mutual] : {std::make_tuple("--lambda_mask 2", 2.0, 1.0),
                                             std::make_tuple("--lambda_mask_warmup 4", 4.0, 1.5)}) {
    SCOPED_TRACE(flag);
    r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                            "/out_mask " + flag + few + " --overwrite");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    ASSERT_TRUE(ReadFileToString(dir + "/out_mask/metrics.json", &metrics).ok());
    EXPECT_DOUBLE_EQ(row_weight(metrics, "mask", "warmup"), warmup);
    EXPECT_DOUBLE_EQ(row_weight(metrics, "mask", "mutual"), mutual);
  }
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/out_mask_bad --lambda_mask_warmup -3" + few);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--lambda_mask_warmup must be >= 0"), std::string::npos) << r.output;
  // --surfel_spread: masked (also when not given) spreads where the views have masks (and says
  // so), on and off decide with or without masks.
  for (const auto& [workspace, value, spread] :
       {std::make_tuple(base_, "", true), std::make_tuple(dir, "", false),
        std::make_tuple(base_, "masked", true), std::make_tuple(dir, "masked", false),
        std::make_tuple(dir, "on", true), std::make_tuple(base_, "off", false)}) {
    SCOPED_TRACE(workspace + " '" + value + "'");
    const std::string flag = *value ? std::string(" --surfel_spread ") + value : std::string();
    r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + workspace + " --output " + dir +
                            "/out_spread --overwrite" + flag + few);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(r.output.find("initial disks: spread over the points' surfaces to the 2DGS budget "
                            "(the views have masks or alpha)") != std::string::npos,
              spread && std::string(value) != "on")
        << r.output;
    ASSERT_TRUE(ReadFileToString(dir + "/out_spread/metrics.json", &metrics).ok());
    EXPECT_EQ(nlohmann::json::parse(metrics)["budget"]["spread_initial_surfels"], spread)
        << metrics;
    // The surfel layer prior follows the spread (--lambda_surfel_layer -1); no rows without it.
    for (const char* stage : {"warmup", "mutual"}) {
      EXPECT_DOUBLE_EQ(row_weight(metrics, "surfel_layer", stage),
                       spread ? SolverOptions::kSurfelLayerWeightWithSpread : -1.0)
          << metrics;
    }
  }
  // Given, its weight is kept: 0 with the spread, 2 without.
  for (const auto& [flags, weight] :
       {std::make_pair(std::string(" --surfel_spread on --lambda_surfel_layer 0"), -1.0),
        std::make_pair(std::string(" --surfel_spread off --lambda_surfel_layer 2"), 2.0)}) {
    r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                            "/out_layer --overwrite" + flags + few);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    ASSERT_TRUE(ReadFileToString(dir + "/out_layer/metrics.json", &metrics).ok());
    EXPECT_DOUBLE_EQ(row_weight(metrics, "surfel_layer", "mutual"), weight) << flags;
  }
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/out_layer_bad --lambda_surfel_layer -2" + few);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--lambda_surfel_layer must be >= 0"), std::string::npos) << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/out_spread_bad --surfel_spread all" + few);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--surfel_spread must be off, on or masked"), std::string::npos)
      << r.output;
  // Given on the command line, the weight is kept as given.
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " + dir +
                          "/out_given --lambda_normal 0.7" + few);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("normal weight:"), std::string::npos) << r.output;
  ASSERT_TRUE(ReadFileToString(dir + "/out_given/metrics.json", &metrics).ok());
  EXPECT_DOUBLE_EQ(normal_row_weight(metrics), 0.7);
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " + dir +
                          "/out_given_distortion --lambda_distortion 0" + few);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("depth distortion:"), std::string::npos) << r.output;
  ASSERT_TRUE(ReadFileToString(dir + "/out_given_distortion/metrics.json", &metrics).ok());
  EXPECT_DOUBLE_EQ(row_weight(metrics, "distortion", "mutual"), 0.0) << metrics;
}

// The progress line's test PSNR scores the same composite as the final evaluation: at the last
// (3DGS) iteration of the run, with a grey background, both print the same figure.
TEST_F(CliTest, ProgressPsnrAgreesWithTheFinalEvaluation) {
  const std::string dir = testing::ScratchDir();
  fs::remove_all(dir);
  const auto r =
      testing::RunCommand(kTools + "/mgsr_solve --workspace " + base_ + " --output " + dir +
                          "/out --warmup_max_iterations 10 "
                          "--warmup_min_iterations 0 --mutual_iterations 4 "
                          "--log_every 100 --eval_every 4 --background 0.5");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string progress = "[mutual     4] test PSNR ";
  const size_t at = r.output.find(progress);
  ASSERT_NE(at, std::string::npos) << r.output;
  const std::string figure = r.output.substr(at + progress.size(), 6);  // e.g. "17.42 "
  EXPECT_NE(r.output.find("test views: PSNR " + figure + "dB"), std::string::npos)
      << "progress " << figure << " vs final: " << r.output;
}

TEST_F(CliTest, MissingWorkspaceFlagAndFolder) {
  auto r = testing::RunCommand(kTools + "/mgsr_solve");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("give either --workspace or --images"), std::string::npos);
  ExpectSolveFails("/nonexistent/scene", "/nonexistent/scene: scene folder does not exist");
}

TEST_F(CliTest, TruncatedCamerasFile) {
  const std::string dir = Copy();
  std::string data;
  ASSERT_TRUE(ReadFileToString(dir + "/sparse/0/cameras.bin", &data).ok());
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/sparse/0/cameras.bin", data.substr(0, 20)).ok());
  ExpectSolveFails(dir, dir + "/sparse/0/cameras.bin: truncated");
}

TEST_F(CliTest, UnknownCameraModelId) {
  const std::string dir = Copy();
  std::string data;
  ASSERT_TRUE(ReadFileToString(dir + "/sparse/0/cameras.bin", &data).ok());
  const int32_t bad = 77;
  std::memcpy(data.data() + 12, &bad, 4);
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/sparse/0/cameras.bin", data).ok());
  ExpectSolveFails(dir, "cameras.bin: camera 1 has unknown camera model id 77");
}

TEST_F(CliTest, ImageListedButMissing) {
  const std::string dir = Copy();
  fs::remove(dir + "/images/v004.png");
  ExpectSolveFails(dir, dir + "/images/v004.png: image file is missing");
}

TEST_F(CliTest, ImageSizeMismatch) {
  const std::string dir = Copy();
  ASSERT_TRUE(WriteImage(dir + "/images/v001.png", Image(31, 32, 3)).ok());
  ExpectSolveFails(dir, dir + "/images/v001.png: image is 31x32 but its camera says 32x32");
}

TEST_F(CliTest, CorruptImage) {
  const std::string dir = Copy();
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/images/v002.png", "\x89PNG garbage").ok());
  ExpectSolveFails(dir, dir + "/images/v002.png: cannot decode image");
}

TEST_F(CliTest, NanPose) {
  const std::string dir = Copy();
  EditModel(dir, [](ColmapModel* m) { m->images[3].tvec.z() = INFINITY; });
  ExpectSolveFails(dir, "image v003.png has a NaN/inf pose");
}

TEST_F(CliTest, ZeroImages) {
  const std::string dir = Copy();
  EditModel(dir, [](ColmapModel* m) {
    m->images.clear();
    m->points.clear();
  });
  ExpectSolveFails(dir, "the model has no images");
}

TEST_F(CliTest, EmptyPointsIsAWarningNotAnError) {
  const std::string dir = Copy();
  EditModel(dir, [](ColmapModel* m) {
    m->points.clear();
    for (auto& im : m->images) {
      im.xys.clear();
      im.point3D_ids.clear();
    }
  });
  const auto r = testing::RunCommand(
      kTools + "/mgsr_solve --workspace " + dir + " --output " + dir +
      "/out --warmup_max_iterations 5 --warmup_min_iterations 0 --mutual_iterations 2");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("warning: " + dir + "/sparse/0: points3D is empty"), std::string::npos)
      << r.output;
}

TEST_F(CliTest, SynthRejectsBadOptions) {
  auto r = testing::RunCommand(kTools + "/mgsr_synth --output " + testing::ScratchDir() +
                               " --shape teapot");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("error: unknown shape 'teapot'"), std::string::npos) << r.output;
  r = testing::RunCommand(kTools + "/mgsr_synth");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--output is required"), std::string::npos) << r.output;
}

TEST_F(CliTest, EvalScoresMeshesAndImagesAndWritesJson) {
  const std::string out = testing::ScratchDir();
  auto r = testing::RunCommand(kTools + "/mgsr_eval --mesh " + base_ + "/gt/mesh.ply --gt " +
                               base_ + "/gt/mesh.ply --json " + out + "/mesh.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::string json;
  ASSERT_TRUE(ReadFileToString(out + "/mesh.json", &json).ok());
  EXPECT_NE(json.find("\"ok\": true"), std::string::npos) << json;
  // The same mesh as binary glTF scores the same against its PLY.
  TriangleMesh gt;
  ASSERT_TRUE(ReadTriangleMesh(base_ + "/gt/mesh.ply", &gt).ok());
  ASSERT_TRUE(WriteMeshGlb(out + "/gt.glb", gt).ok());
  r = testing::RunCommand(kTools + "/mgsr_eval --mesh " + out + "/gt.glb --gt " + base_ +
                          "/gt/mesh.ply --json " + out + "/glb.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json a = nlohmann::json::parse(json), b;
  ASSERT_TRUE(ReadFileToString(out + "/glb.json", &json).ok());
  b = nlohmann::json::parse(json);
  EXPECT_NEAR(b["mesh"]["cd"].get<double>(), a["mesh"]["cd"].get<double>(), 1e-6) << json;
  EXPECT_NEAR(b["mesh"]["nc"].get<double>(), a["mesh"]["nc"].get<double>(), 1e-6) << json;
  r = testing::RunCommand(kTools + "/mgsr_eval --renders " + base_ + "/images --gt_images " +
                          base_ + "/images --json " + out + "/images.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("mean                      100.000   1.0000    100.000     1.0000"),
            std::string::npos)
      << r.output;
}

TEST_F(CliTest, EvalBadInput) {
  const std::string dir = Copy();
  auto r = testing::RunCommand(kTools + "/mgsr_eval --mesh " + dir + "/nope.ply --gt " + dir +
                               "/gt/mesh.ply");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output, "error: " + dir + "/nope.ply: cannot open (missing or unreadable)\n");
  ASSERT_TRUE(WriteImage(dir + "/masks/v001.png", Image(16, 16, 1)).ok());
  r = testing::RunCommand(kTools + "/mgsr_eval --renders " + dir + "/masks --gt_images " + dir +
                          "/images");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("error: " + dir + "/masks/v001.png: render is 16x16 but"),
            std::string::npos)
      << r.output;
  r = testing::RunCommand(kTools + "/mgsr_eval --mesh a.ply");
  EXPECT_EQ(r.exit_code, 2);
}

TEST_F(CliTest, PhotoPipelineBadInput) {
  const std::string dir = Copy();
  auto r = testing::RunCommand(kTools + "/mgsr_colmap --images " + dir + "/nope --workspace " +
                               dir + "/ws");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output, "error: " + dir + "/nope: folder of photos does not exist\n");
  r = testing::RunCommand(kTools + "/mgsr_colmap --images " + dir + "/images --workspace " + dir +
                          "/ws --colmap " + dir + "/no_colmap");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output.rfind("error: " + dir + "/no_colmap: program not found", 0), 0u) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  r = testing::RunCommand(kTools + "/mgsr_solve --images " + dir + "/images --output " + dir +
                          "/out --colmap " + dir + "/no_colmap");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.output.rfind("error: " + dir + "/no_colmap: program not found", 0), 0u) << r.output;
  EXPECT_FALSE(FileExists(dir + "/out/metrics.json"));
  r = testing::RunCommand(kTools + "/mgsr_solve --images " + dir + "/images --workspace " + dir +
                          " --output " + dir + "/out");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.output, "error: give either --workspace or --images\n");
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

TEST_F(CliTest, LossConfigChangesTheTableAndTheLogShowsEachRow) {
  // --list_losses needs no scene.
  auto r = testing::RunCommand(kTools + "/mgsr_solve --list_losses --lambda_normal 0.5");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("normal_consistency   normal depth [alpha]"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("2d     warmup  normal_consistency   normal_consistency         0.5"),
            std::string::npos)
      << r.output;
  const std::string dir = Copy();
  {
    std::ofstream(dir + "/losses.json")
        << R"({"losses": [{"branch": "3d", "stage": "warmup", "name": "depth_tv", "weight": 0},
              {"branch": "3d", "stage": "warmup", "name": "tran_l1", "term": "l1",
               "config": {"buffer": "transmitted", "target": "image"}, "weight": 0.01}]})";
  }
  // A bad row: one line naming the file and the row, nothing written.
  {
    std::ofstream(dir + "/bad.json")
        << R"({"losses": [{"branch": "3d", "stage": "warmup", "name": "x", "term": "l2",
              "weight": 1}]})";
  }
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " + dir +
                          "/bad_out --loss_config " + dir + "/bad.json");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output.rfind("error: " + dir +
                               "/bad.json: loss row 3d/warmup/x: unknown loss term "
                               "'l2'",
                           0),
            0u)
      << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/bad_out"));
  r = testing::RunCommand(kTools + "/mgsr_solve --workspace " + dir + " --output " + dir +
                          "/out --warmup_max_iterations 20 --warmup_min_iterations 0 "
                          "--mutual_iterations 4 --checkpoint_every 0 --loss_config " +
                          dir + "/losses.json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream log(dir + "/out/log.csv");
  std::string header, line, warm_3d;
  std::getline(log, header);
  EXPECT_EQ(header, "stage,iteration,branch,loss,gaussians,surfels,seconds,terms");
  while (std::getline(log, line)) {
    if (line.rfind("warmup,10,3dgs,", 0) == 0) warm_3d = line;
  }
  // The 3DGS warm-up rows: the photo, the transmitted TV, the new row; depth_tv is switched off.
  EXPECT_NE(warm_3d.find(",photo="), std::string::npos) << warm_3d;
  EXPECT_NE(warm_3d.find(";transmitted_tv="), std::string::npos) << warm_3d;
  EXPECT_NE(warm_3d.find(";tran_l1="), std::string::npos) << warm_3d;
  EXPECT_EQ(warm_3d.find("depth_tv"), std::string::npos) << warm_3d;
  std::string metrics;
  ASSERT_TRUE(ReadFileToString(dir + "/out/metrics.json", &metrics).ok());
  const nlohmann::json m = nlohmann::json::parse(metrics);
  ASSERT_TRUE(m["losses"].is_array());
  // The default 22 rows, the surfel layer prior's two (the views have masks) and the new one.
  EXPECT_EQ(m["losses"].size(), 25u);
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// --help: each tool's own flags by topic, with defaults; none of glog's or gflags' own, and none
// left out of a topic.
TEST(CliHelpTest, HelpShowsTheToolsOwnFlagsByTopic) {
  for (const char* tool :
       {"mgsr_solve", "mgsr_eval", "mgsr_synth", "mgsr_colmap", "mgsr_bench", "mgsr_render"}) {
    const auto r = testing::RunCommand(kTools + "/" + tool + " --help");
    EXPECT_EQ(r.exit_code, 0) << tool << r.output;
    EXPECT_EQ(r.output.rfind(std::string("usage: ") + tool, 0), 0u) << r.output;
    EXPECT_EQ(r.output.find("--logtostderr"), std::string::npos) << tool;
    EXPECT_EQ(r.output.find("--flagfile"), std::string::npos) << tool;
    EXPECT_EQ(r.output.find("\nOther:"), std::string::npos) << tool << ": a flag without a topic";
  }
  const auto r = testing::RunCommand(kTools + "/mgsr_solve --help");
  EXPECT_NE(r.output.find("\nLosses:\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("  --lambda_normal (double, default -1)\n"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("  --preset (string, default \"fast\")\n"), std::string::npos)
      << r.output;
}

}  // namespace
}  // namespace mgsr

namespace mgsr {
namespace {

// "--overwrite false" is gflags' bare --overwrite (true) and a stray word: every tool refuses the
// word with one line, before doing anything (a finished run must not be replaced).
TEST(CliArgumentsTest, StrayPositionalWordsAreRefusedByEveryTool) {
  const std::string dir = testing::ScratchDir();
  for (const char* tool :
       {"mgsr_solve", "mgsr_eval", "mgsr_synth", "mgsr_colmap", "mgsr_bench", "mgsr_render"}) {
    const auto r = testing::RunCommand(kTools + "/" + tool + " false");
    EXPECT_EQ(r.exit_code, 2) << tool << r.output;
    EXPECT_EQ(r.output.rfind("error: unexpected argument 'false'", 0), 0u) << tool << r.output;
    EXPECT_NE(r.output.find("--overwrite=false"), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << tool << r.output;
  }
  // The audit's case: "--masks false" must not write a scene with masks.
  const auto r =
      testing::RunCommand(kTools + "/mgsr_synth --output " + dir + "/scene --masks false");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir + "/scene")) << "nothing may be written";
}

}  // namespace
}  // namespace mgsr
