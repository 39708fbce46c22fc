// The benchmark harness: failure classification, the Pareto front, and a whole (tiny) quick run of
// mgsr_bench whose report files must exist and parse.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "benchmarks/harness/finished_runs.h"
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

// A report written from records reads back to the same records, and its comparison sections
// state MGSR's differences against the single-branch methods and exposure on against off.
TEST(HarnessTest, ResultsCsvRoundTripsAndComparisonsAreWritten) {
  const std::string dir = testing::ScratchDir();
  ReportContext c;
  c.command = "mgsr_bench --test";
  c.commit = "abc1234";
  c.date = "2026-01-01 00:00 UTC";
  c.machine = "test CPU, 2 cores";
  c.threads = 2;
  c.main_scene = "main";
  c.scenes = {{"main", "specular, varying light", {}, 0, true}};
  c.methods = {{"mgsr", "both", {}, Coverage::kAll},
               {"2dgs", "2DGS alone", {}, Coverage::kAll},
               {"3dgs", "3DGS alone", {}, Coverage::kAll},
               {"mgsr-no-exposure", "off", {}, Coverage::kVaryingLight}};
  auto record = [&](const std::string& method, double nc, double psnr, bool ok) {
    RunRecord r;
    r.scene = "main";
    r.method = method;
    r.run_dir = JoinPath(dir, "runs/main/" + method);
    r.ok = ok;
    r.failure = ok ? "" : "error: a, \"quoted\" failure";
    r.measured = true;
    r.nc = nc;
    r.cd = 0.02;
    r.psnr = psnr;
    r.ssim = 0.9;
    r.psnr_aligned = psnr + 3;
    r.ssim_aligned = 0.95;
    r.t_total = 100;
    r.wall_seconds = 101.5;
    r.gaussians = 1000;
    return r;
  };
  std::vector<RunRecord> runs = {record("mgsr", 0.95, 24.5, true), record("2dgs", 0.93, 20, true),
                                 record("3dgs", 0.85, 25.25, false),
                                 record("mgsr-no-exposure", 0.94, 23, true)};
  RunRecord crashed;  // no numbers at all
  crashed.scene = "main";
  crashed.method = "3dgs-ref";
  crashed.failure = "crash (signal 11)";
  crashed.wall_seconds = 3;
  runs.push_back(crashed);
  ASSERT_TRUE(WriteReport(dir, c, runs).ok());

  std::vector<RunRecord> back;
  ASSERT_TRUE(ReadResultsCsv(JoinPath(dir, "results.csv"), dir, &back).ok());
  ASSERT_EQ(back.size(), runs.size());
  for (size_t i = 0; i < runs.size(); ++i) {
    EXPECT_EQ(back[i].method, runs[i].method);
    EXPECT_EQ(back[i].ok, runs[i].ok);
    EXPECT_EQ(back[i].failure, runs[i].failure);
    EXPECT_EQ(back[i].measured, runs[i].measured) << runs[i].method;
    EXPECT_EQ(back[i].run_dir, JoinPath(dir, "runs/main/" + runs[i].method));
    EXPECT_DOUBLE_EQ(back[i].wall_seconds, runs[i].wall_seconds);
    if (runs[i].measured) {
      EXPECT_DOUBLE_EQ(back[i].nc, runs[i].nc);
      EXPECT_DOUBLE_EQ(back[i].psnr_aligned, runs[i].psnr_aligned);
    } else {
      EXPECT_TRUE(std::isnan(back[i].nc));
    }
  }
  ReportContext saved;
  ASSERT_TRUE(ReadReportContext(JoinPath(dir, "context.json"), &saved).ok());
  EXPECT_EQ(saved.commit, "abc1234");
  EXPECT_EQ(saved.command, c.command);
  EXPECT_EQ(saved.threads, 2);

  std::string md;
  ASSERT_TRUE(ReadFileToString(JoinPath(dir, "README.md"), &md).ok());
  // MGSR minus 2dgs on NC: 95 - 93 = +2.00; minus 3dgs on PSNR: 24.5 - 25.25 = -0.75.
  EXPECT_NE(md.find("## Main case (main)"), std::string::npos) << md;
  EXPECT_NE(md.find("| 2dgs | 93.00 | +2.00 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| 25.25 | -0.75 |"), std::string::npos) << md;
  EXPECT_NE(md.find("## Exposure compensation on the varying-light scenes"), std::string::npos);
  EXPECT_NE(md.find("| main | 94.00 | 95.00 |"), std::string::npos) << md;

  // Bad input: a CSV that is not the harness's, and a truncated row.
  ASSERT_TRUE(WriteStringToFileAtomic(JoinPath(dir, "bad.csv"), "a,b\n").ok());
  EXPECT_FALSE(ReadResultsCsv(JoinPath(dir, "bad.csv"), dir, &back).ok());
  std::string csv;
  ASSERT_TRUE(ReadFileToString(JoinPath(dir, "results.csv"), &csv).ok());
  ASSERT_TRUE(
      WriteStringToFileAtomic(JoinPath(dir, "cut.csv"), csv.substr(0, csv.size() - 20)).ok());
  const Status cut = ReadResultsCsv(JoinPath(dir, "cut.csv"), dir, &back);
  EXPECT_FALSE(cut.ok());
  EXPECT_NE(cut.message().find("cut.csv: line 6"), std::string::npos) << cut.message();
}

TEST(HarnessTest, SuiteCoversTheStressCasesAndMethods) {
  std::vector<std::string> scenes, methods;
  for (const SceneSpec& s : Scenes(false)) scenes.push_back(s.name);
  for (const MethodSpec& m : Methods(false)) methods.push_back(m.name);
  for (const char* s : {"control", "main", "exposure", "mirror", "sparse", "thin", "noisy_poses",
                        "no_masks", "outdoor", "indoor_mirror"}) {
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

TEST(HarnessTest, BudgetListsBecomeMcmcRunsAndTheReference) {
  std::vector<MethodSpec> m;
  ASSERT_TRUE(BudgetMethods("2k,5000,auto", &m).ok());
  ASSERT_EQ(m.size(), 4u);
  EXPECT_EQ(m[0].name, "mcmc-2k");
  EXPECT_EQ(m[0].solve_args, (std::vector<std::string>{"--density", "mcmc", "--budget", "2000"}));
  EXPECT_EQ(m[1].solve_args.back(), "5000");
  EXPECT_EQ(m[2].solve_args.back(), "auto");
  EXPECT_EQ(m[3].name, "reference");
  EXPECT_EQ(m[3].solve_args, (std::vector<std::string>{"--density", "reference"}));
  for (const char* bad : {"", "2k,2000", "lots", "0", "5m", "2k,,"}) {
    const Status s = BudgetMethods(bad, &m);
    EXPECT_FALSE(s.ok()) << bad;
    EXPECT_EQ(s.message().rfind("--budgets: ", 0), 0u) << s.message();
  }
}

// The quality-size section: rows by size, the share of the reference, which runs reach it, the
// smallest that does, and auto against the curve; an old 22-column results.csv still reads.
TEST(HarnessTest, BudgetStudyFindsTheSmallestRunReachingTheReference) {
  const std::string dir = testing::ScratchDir();
  ReportContext c;
  c.main_scene = "main";
  c.budget_study = true;
  c.scenes = {{"main", "specular", {}, 0, true}};
  ASSERT_TRUE(BudgetMethods("2k,5k,10k,auto", &c.methods).ok());
  auto record = [&](const std::string& method, double g, double s, double nc, double psnr) {
    RunRecord r;
    r.scene = "main";
    r.method = method;
    r.run_dir = JoinPath(dir, "runs/main/" + method);
    r.ok = r.measured = true;
    r.nc = nc;
    r.cd = 0.005;
    r.psnr = r.psnr_aligned = psnr;
    r.ssim = 0.9;
    r.gaussians = g;
    r.surfels = s;
    r.t_warmup = 30;
    r.t_mutual = 20;
    r.t_total = 60;
    r.iterations = 1000;
    return r;
  };
  // 5k reaches the reference (NC -0.15 points, PSNR -0.1 dB); 2k does not (NC -0.5).
  const std::vector<RunRecord> runs = {
      record("reference", 20000, 20000, 0.9600, 26.0),
      record("mcmc-10k", 10000, 10000, 0.9610, 26.1), record("mcmc-2k", 2000, 2000, 0.9550, 25.5),
      record("mcmc-5k", 5000, 5000, 0.9585, 25.9), record("mcmc-auto", 5500, 5500, 0.9586, 25.9)};
  ASSERT_TRUE(WriteReport(dir, c, runs).ok());
  std::string md;
  ASSERT_TRUE(ReadFileToString(JoinPath(dir, "README.md"), &md).ok());
  const size_t section = md.find("## Quality against model size");
  ASSERT_NE(section, std::string::npos) << md;
  const size_t at2 = md.find("| mcmc-2k | 2000 | 2000 | 10% |", section),
               at5 = md.find("| mcmc-5k |", section);
  ASSERT_NE(at2, std::string::npos) << md;
  EXPECT_LT(at2, at5);  // ordered by size
  EXPECT_NE(md.find("| 25.50 | 50.0 | 60 | no |"), std::string::npos) << md;
  EXPECT_NE(md.find("**mcmc-5k**, 10000 primitives (25% of the reference's)"), std::string::npos)
      << md;
  EXPECT_NE(md.find("`--budget auto` chose 11000 primitives; the smallest run reaching its "
                    "quality is mcmc-5k with 10000 (+10%"),
            std::string::npos)
      << md;
  ReportContext saved;
  ASSERT_TRUE(ReadReportContext(JoinPath(dir, "context.json"), &saved).ok());
  EXPECT_TRUE(saved.budget_study);

  // results.csv of the older layouts (no normal_deg column; no iterations either) still read back.
  std::string csv;
  ASSERT_TRUE(ReadFileToString(JoinPath(dir, "results.csv"), &csv).ok());
  std::string older, oldest;
  std::istringstream lines(csv);
  for (std::string line; std::getline(lines, line);) {
    line = line.substr(0, line.rfind(','));
    older += line + "\n";
    oldest += line.substr(0, line.rfind(',')) + "\n";
  }
  ASSERT_TRUE(WriteStringToFileAtomic(JoinPath(dir, "older.csv"), older).ok());
  ASSERT_TRUE(WriteStringToFileAtomic(JoinPath(dir, "old.csv"), oldest).ok());
  std::vector<RunRecord> back;
  ASSERT_TRUE(ReadResultsCsv(JoinPath(dir, "older.csv"), dir, &back).ok());
  ASSERT_EQ(back.size(), runs.size());
  EXPECT_DOUBLE_EQ(back[0].iterations, 1000);
  EXPECT_TRUE(std::isnan(back[0].normal_deg));
  ASSERT_TRUE(ReadResultsCsv(JoinPath(dir, "old.csv"), dir, &back).ok());
  ASSERT_EQ(back.size(), runs.size());
  EXPECT_TRUE(std::isnan(back[0].iterations));
  EXPECT_DOUBLE_EQ(back[0].nc, 0.96);
  ASSERT_TRUE(ReadResultsCsv(JoinPath(dir, "results.csv"), dir, &back).ok());
  EXPECT_DOUBLE_EQ(back[0].iterations, 1000);
}

// A tiny --quick run end to end: every report file exists and parses.
TEST(HarnessTest, ResumeKeepsOnlyRunsFinishedWithTheSameCommandAndCommit) {
  const std::string run = testing::ScratchDir() + "/runs/main/mgsr";
  ASSERT_TRUE(MakeDirectories(run).ok());
  const std::vector<std::string> cmd = {"mgsr_solve", "--workspace", "w", "--preset", "fast"};
  double wall = -1;
  ASSERT_TRUE(MarkRunFinished(run, cmd, "abc1234", 12.5).ok());
  // No metrics.json: the run did not leave its results, so it is not kept.
  EXPECT_FALSE(FinishedEarlier(run, cmd, "abc1234", &wall));
  ASSERT_TRUE(WriteStringToFileAtomic(run + "/metrics.json", "{}").ok());
  EXPECT_TRUE(FinishedEarlier(run, cmd, "abc1234", &wall));
  EXPECT_EQ(wall, 12.5);

  std::vector<std::string> other = cmd;
  other.back() = "paper";
  EXPECT_FALSE(FinishedEarlier(run, other, "abc1234", &wall));
  other = cmd;
  other.push_back("--seed");
  EXPECT_FALSE(FinishedEarlier(run, other, "abc1234", &wall));
  EXPECT_FALSE(FinishedEarlier(run, cmd, "def5678", &wall));
  // A tree with uncommitted changes cannot vouch for the code a run used.
  const std::string dirty = "abc1234 (with uncommitted changes)";
  ASSERT_TRUE(MarkRunFinished(run, cmd, dirty, 12.5).ok());
  EXPECT_FALSE(FinishedEarlier(run, cmd, dirty, &wall));

  ASSERT_TRUE(WriteStringToFileAtomic(run + ".done", "{\"command\": [1, 2]").ok());
  EXPECT_FALSE(FinishedEarlier(run, cmd, "abc1234", &wall));
  ASSERT_TRUE(MarkRunFinished(run, cmd, "abc1234", 3).ok());
  ForgetRun(run);
  EXPECT_FALSE(FileExists(run + ".done"));
  EXPECT_FALSE(FinishedEarlier(run, cmd, "abc1234", &wall));
}

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
    EXPECT_EQ(commas, 23u) << line;
    if (rows > 0) {
      // Every run has a mesh here: its signed offset and the exact-depth ceiling are filled in.
      std::vector<std::string> fields;
      std::istringstream f(line);
      for (std::string v; std::getline(f, v, ',');) fields.push_back(v);
      ASSERT_EQ(fields.size(), 24u) << line;
      for (int k : {18, 20, 21, 22, 23}) EXPECT_FALSE(fields[k].empty()) << k << ": " << line;
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
  EXPECT_NE(md.find("## Main case (main)"), std::string::npos);

  // --report_only rebuilds the same tables from results.csv without running anything.
  const auto rebuilt = testing::RunCommand(std::string(MGSR_TOOLS_DIR) +
                                           "/mgsr_bench --quick --report_only --output " + out);
  ASSERT_EQ(rebuilt.exit_code, 0) << rebuilt.output;
  std::string md2;
  ASSERT_TRUE(ReadFileToString(out + "/README.md", &md2).ok());
  EXPECT_NE(md2.find("rebuilt from this run's results.csv"), std::string::npos);
  const size_t from = md.find("## Results per scene"), to = md.find("## Charts");
  EXPECT_EQ(md2.substr(md2.find("## Results per scene"), to - from), md.substr(from, to - from));
  const auto missing = testing::RunCommand(std::string(MGSR_TOOLS_DIR) +
                                           "/mgsr_bench --report_only --output " + out + "/none");
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_NE(missing.output.find("context.json"), std::string::npos) << missing.output;
  if (!FindProgram("gnuplot").empty()) {
    for (const char* chart : {"time_vs_nc", "time_vs_psnr", "count_vs_psnr"})
      EXPECT_TRUE(FileExists(out + "/charts/" + chart + ".png")) << chart;
  }
}

}  // namespace
}  // namespace mgsr::bench
