// The harness's report: what each run measured (read from its metrics.json), whether it failed and
// why, and the files a person reads: CSV, markdown tables, the stability matrix, charts (gnuplot)
// and contact sheets.
#pragma once

#include <string>
#include <vector>

#include "benchmarks/harness/suite.h"
#include "mgsr/core/status.h"

namespace mgsr::bench {

struct RunRecord {
  std::string scene, method;
  std::string run_dir;  // mgsr_solve's --output
  bool ok = false;
  bool measured = false;  // metrics.json was read (also for runs failed on a threshold)
  std::string failure;    // "", "NaN", "crash (signal 11)", "error: ...", "empty mesh", ...
  double wall_seconds = 0;
  // From metrics.json (NaN when absent).
  double nc, cd, psnr, ssim, psnr_aligned, ssim_aligned;
  // Exact geometry (point to triangle): the median signed offset in training pixel footprints
  // (negative: inside), the F-score at one footprint, and the exact-depth ceiling's NC and CD.
  double offset_px, fscore_1px, ceiling_nc, ceiling_cd;
  // The mean angle between the rendered 2DGS normals and the true ones on the training views
  // (degrees): relief smoothed away or texture copied into the geometry shows here.
  double normal_deg;
  double t_warmup, t_mutual, t_mesh, t_total, peak_mb;
  double gaussians, surfels;
  // Training iterations: the longer branch's warm-up plus the mutual stage (an iteration steps
  // every branch that trains in that stage), so (t_warmup + t_mutual) / iterations is the
  // cost of one.
  double iterations;
  RunRecord();
};

struct ReportContext {
  std::string title = "MGSR-CPU benchmark";
  std::string command;  // how the report was made
  std::string commit, date, machine;
  int threads = 0;
  double nc_threshold = 0.8;  // NC below this is a failed reconstruction
  std::vector<SceneSpec> scenes;
  std::vector<MethodSpec> methods;
  std::string main_scene;
  std::string rebuilt;  // when the report was rebuilt from results.csv (--report_only), else ""
  // A quality-size study (mgsr_bench --budgets): the report adds, per scene, the runs ordered by
  // model size and the smallest budget that reaches the reference strategy's quality.
  bool budget_study = false;
};

// Classifies a finished run from its exit and metrics.json: fills ok / failure and the numbers.
void ReadRunResult(int exit_code, int signal, bool timed_out, double timeout_seconds,
                   const std::string& log_tail, double nc_threshold, RunRecord* record);

// Writes results.csv, README.md (tables, stability matrix, links), charts/*.png (when gnuplot
// is available; the report says when it is not) and contact/<scene>.png into `dir`.
Status WriteReport(const std::string& dir, const ReportContext& context,
                   const std::vector<RunRecord>& runs);

// Reads the runs back from a report's results.csv (as WriteReport wrote it); run_dir is
// `work`/runs/<scene>/<method>, where mgsr_bench put the run. A run counts as measured when any of
// its numbers is present.
Status ReadResultsCsv(const std::string& path, const std::string& work,
                      std::vector<RunRecord>* runs);

// The report's context (title, command, commit, date, machine, threads, threshold, main scene)
// as WriteReport stores it in context.json; scenes and methods are left to the caller.
Status ReadReportContext(const std::string& path, ReportContext* context);

// Milliseconds per training iteration (NaN when unknown).
double MsPerIteration(const RunRecord& r);

// Pareto front of points (cost x lower is better, quality y higher is better): indices of the
// points no other point beats in both, sorted by x.
std::vector<int> ParetoFront(const std::vector<double>& x, const std::vector<double>& y);

}  // namespace mgsr::bench
