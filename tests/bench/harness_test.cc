// The benchmark harness: failure classification, the Pareto front, and a whole (tiny) quick run of
// mgsr_bench whose report files must exist and parse.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "benchmarks/harness/report.h"
#include "benchmarks/harness/suite.h"
#include "mgsr/core/subprocess.h"
#include "mgsr/io/file_util.h"
#include "test_util.h"

namespace mgsr::bench {
namespace {

TEST(HarnessTest, ParetoFrontKeepsOnlyUnbeatenPoints) {
  // (time, quality): 1 is beaten by 0 (slower and worse), 3 by 2.
  const std::vector<double> x = {1, 2, 3, 4, 0.5}, y = {5, 4, 7, 6, 1};
  EXPECT_EQ(ParetoFront(x, y), (std::vector<int>{4, 0, 2}));
  EXPECT_TRUE(ParetoFront({}, {}).empty());
}

TEST(HarnessTest, ClassifiesFailures) {
  const std::string dir = testing::ScratchDir();
  RunRecord r;
  r.run_dir = dir;
  ReadRunResult(0, 0, true, 60, "", 0.8, &r);
  EXPECT_EQ(r.failure, "timeout after 60 s");
  ReadRunResult(139, 11, false, 60, "", 0.8, &r);
  EXPECT_EQ(r.failure, "crash (signal 11)");
  ReadRunResult(1, 0, false, 60, "[warmup 100] ...\nerror: scene.bin: truncated\n", 0.8, &r);
  EXPECT_EQ(r.failure, "error: scene.bin: truncated");
  ReadRunResult(0, 0, false, 60, "", 0.8, &r);
  EXPECT_EQ(r.failure, "no metrics.json");
  auto metrics = [&](const std::string& json) {
    ASSERT_TRUE(WriteStringToFileAtomic(JoinPath(dir, "metrics.json"), json).ok());
    ReadRunResult(0, 0, false, 60, "", 0.8, &r);
  };
  metrics(R"({"test": {"psnr": null, "ssim": 0.5}, "mesh": {"triangles": 10, "nc": 0.9}})");
  EXPECT_EQ(r.failure, "NaN in the test scores");
  metrics(R"({"test": {"psnr": 20, "ssim": 0.5}, "mesh": {"triangles": 0}})");
  EXPECT_EQ(r.failure, "empty mesh");
  metrics(R"({"test": {"psnr": 20, "ssim": 0.5}, "mesh": {"triangles": 10, "nc": 0.5}})");
  EXPECT_EQ(r.failure, "NC 0.500 below 0.80");
  EXPECT_TRUE(r.measured);
  metrics(R"({"test": {"psnr": 20, "ssim": 0.5}, "mesh": {"triangles": 10, "nc": 0.95},
              "seconds": {"total": 12.5}, "counts": {"gaussians": 100, "surfels": 50}})");
  EXPECT_TRUE(r.ok) << r.failure;
  EXPECT_DOUBLE_EQ(r.t_total, 12.5);
  EXPECT_DOUBLE_EQ(r.gaussians, 100);
}

TEST(HarnessTest, SuiteCoversTheStressCasesAndMethods) {
  std::vector<std::string> scenes, methods;
  for (const SceneSpec& s : Scenes(false)) scenes.push_back(s.name);
  for (const MethodSpec& m : Methods(false)) methods.push_back(m.name);
  for (const char* s :
       {"control", "main", "exposure", "mirror", "sparse", "thin", "noisy_poses", "no_masks"}) {
    EXPECT_NE(std::find(scenes.begin(), scenes.end(), s), scenes.end()) << s;
  }
  for (const char* m :
       {"mgsr", "2dgs", "3dgs", "3dgs-ref", "K-bidirectional", "L-no-autostop", "joint",
        "C-w3d-0.7", "D-w2d-0.7", "F-wdepth-0.1", "G-mutual-x0.25", "mgsr-no-exposure"}) {
    EXPECT_NE(std::find(methods.begin(), methods.end(), m), methods.end()) << m;
  }
  EXPECT_EQ(Scenes(true).size(), 2u);
  EXPECT_EQ(Methods(true).size(), 4u);
}

// A tiny --quick run end to end: every report file exists and parses.
TEST(HarnessTest, QuickRunWritesAReportThatParses) {
  const std::string out = testing::ScratchDir();
  const auto r = testing::RunCommand(
      std::string(MGSR_TOOLS_DIR) + "/mgsr_bench --quick --output " + out +
      " --size 32 --views 12 --solve_flags '--warmup_max_iterations 40 --warmup_min_iterations 0 "
      "--mutual_iterations 20'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("mgsr_bench: 8 runs"), std::string::npos) << r.output;

  std::string csv;
  ASSERT_TRUE(ReadFileToString(out + "/results.csv", &csv).ok());
  std::istringstream lines(csv);
  std::string line;
  int rows = 0;
  while (std::getline(lines, line)) {
    const size_t commas = std::count(line.begin(), line.end(), ',');
    EXPECT_EQ(commas, 17u) << line;
    if (rows > 0) {
      EXPECT_TRUE(line.rfind("control,", 0) == 0 || line.rfind("main,", 0) == 0) << line;
      EXPECT_TRUE(line.find(",ok,") != std::string::npos ||
                  line.find(",failed,") != std::string::npos)
          << line;
    }
    ++rows;
  }
  EXPECT_EQ(rows, 9);  // header + 2 scenes x 4 methods

  std::string md;
  ASSERT_TRUE(ReadFileToString(out + "/README.md", &md).ok());
  for (const char* section : {"## Results per scene", "## Averages", "## Stability matrix",
                              "## Charts", "## Contact sheets", "commit `", "Machine: "}) {
    EXPECT_NE(md.find(section), std::string::npos) << section;
  }
  EXPECT_TRUE(FileExists(out + "/contact/main.png"));
  EXPECT_TRUE(FileExists(out + "/runs/main/mgsr/metrics.json"));
  if (!FindProgram("gnuplot").empty()) {
    for (const char* chart : {"time_vs_nc", "time_vs_psnr", "count_vs_psnr"})
      EXPECT_TRUE(FileExists(out + "/charts/" + chart + ".png")) << chart;
  }
}

}  // namespace
}  // namespace mgsr::bench
