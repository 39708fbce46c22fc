// mgsr_bench: the benchmark harness. Generates the scene suite with mgsr_synth, runs every method
// on every scene with mgsr_solve (one run at a time, each in its own process with a time limit),
// and writes a report folder: results.csv, README.md (tables per scene and averaged, stability
// matrix), charts/ (gnuplot) and contact/ sheets. Every number comes from the runs it made.
#include <gflags/gflags.h>
#include <unistd.h>

#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "benchmarks/harness/finished_runs.h"
#include "benchmarks/harness/report.h"
#include "benchmarks/harness/suite.h"
#include "mgsr/core/progress.h"
#include "mgsr/core/subprocess.h"
#include "mgsr/core/timer.h"
#include "mgsr/io/file_util.h"
#include "tools/openmp_wait.h"
#include "tools/tool_flags.h"

DEFINE_string(output, "", "Report folder (created): README.md, results.csv, charts/, contact/.");
DEFINE_string(work, "", "Folder for the generated scenes/ and runs/ (default: the report folder).");
DEFINE_bool(quick, false,
            "The quick subset: 2 scenes (control, main) x the 4 methods, 48 px, 16 views.");
DEFINE_string(scenes, "", "Comma-separated scene names to run (default: the whole suite).");
DEFINE_string(methods, "", "Comma-separated method names to run (default: all of the suite).");
DEFINE_int32(size, 0, "Image width and height (0: 64, or 48 with --quick).");
DEFINE_int32(views, 0, "Views per scene (0: 32, or 16 with --quick).");
DEFINE_string(solve_flags, "", "Extra flags for every mgsr_solve run (space-separated).");
DEFINE_double(timeout, 1200, "Seconds a run may take before it is stopped and counted failed.");
DEFINE_double(nc_threshold, 0.8, "A mesh with NC below this counts as a failed reconstruction.");
DEFINE_bool(report_only, false,
            "Rebuild README.md, charts and contact sheets from --output's results.csv and "
            "context.json (and the renders under --work) without running anything.");
DEFINE_bool(resume, false,
            "Keep the runs of an earlier, stopped mgsr_bench into the same --work folder that "
            "finished with the same mgsr_solve command at the same commit; run only the rest.");
DEFINE_string(title, "MGSR-CPU benchmark", "Title of the report.");
DEFINE_string(budgets, "",
              "Instead of the methods: the quality-size study. Runs the MCMC density strategy at "
              "each budget of the list (a count per branch, e.g. 2k,5k,10k,20k,auto) and the "
              "reference strategy once, on the main scene (or --scenes / --workspace), and adds "
              "the curve and the smallest budget reaching the reference's quality to the report.");
DEFINE_string(workspace, "",
              "Run on this existing workspace (COLMAP or NeRF layout, e.g. ../shared/data/suzanne) "
              "instead of the generated scenes; the scene is named after its folder.");
DEFINE_string(shared_data, MGSR_SOURCE_DIR "/../shared/data",
              "The shared data folder (meshes for the detailed scenes); a scene whose file is "
              "missing there is skipped.");
DEFINE_bool(profile, false,
            "Instead of the suite: where an iteration's time goes. Generates a 256 px, 48-view "
            "specular object (or --size/--views), runs mgsr_solve --profile on it and writes "
            "profile.txt (ms per iteration per stage and branch) and the run under --output.");
DEFINE_int32(profile_iterations, 0,
             "With --profile: iterations of the warm-up and of the mutual stage (0: the fast "
             "preset's whole schedule, auto-stop included, which is what a user's run costs).");

namespace {

namespace fs = std::filesystem;

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string item;
  std::istringstream in(s);
  while (std::getline(in, item, sep)) {
    if (!item.empty()) out.push_back(item);
  }
  return out;
}

bool Selected(const std::string& list, const std::string& name) {
  if (list.empty()) return true;
  for (const std::string& n : Split(list, ',')) {
    if (n == name) return true;
  }
  return false;
}

std::string ToolDir() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string(".") : self.parent_path().string();
}

// The output of a short command (its first line), "" when it fails.
std::string FirstLineOf(const std::vector<std::string>& argv, const std::string& scratch) {
  std::error_code ec;
  fs::remove(scratch, ec);
  const mgsr::ProgramResult r = mgsr::RunProgram(argv, {}, scratch);
  std::string text;
  if (r.exit_code != 0 || !mgsr::ReadFileToString(scratch, &text).ok()) return "";
  fs::remove(scratch, ec);
  return text.substr(0, text.find('\n'));
}

std::string Commit(const std::string& scratch) {
  const std::string git = mgsr::FindProgram("git");
  if (git.empty()) return "unknown";
  const std::string head =
      FirstLineOf({git, "-C", MGSR_SOURCE_DIR, "rev-parse", "--short", "HEAD"}, scratch);
  if (head.empty()) return "unknown";
  // The committed report is not the code: benchmarks/run deletes it before a full run.
  const std::string dirty =
      FirstLineOf({git, "-C", MGSR_SOURCE_DIR, "status", "--porcelain", "--untracked-files=no",
                   "--", ".", ":(exclude)benchmarks/report", ":(exclude)BENCHMARKS.md"},
                  scratch);
  return head + (dirty.empty() ? "" : " (with uncommitted changes)");
}

std::string Machine() {
  std::ifstream in("/proc/cpuinfo");
  std::string line, model = "unknown CPU";
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  }
  return model + ", " + std::to_string(std::thread::hardware_concurrency()) + " cores";
}

std::string Now() {
  const std::time_t t = std::time(nullptr);
  char buf[64];
  std::strftime(buf, sizeof(buf), "%Y-%m-%d %H:%M UTC", std::gmtime(&t));
  return buf;
}

std::string Tail(const std::string& path, size_t bytes) {
  std::string text;
  if (!mgsr::ReadFileToString(path, &text).ok()) return "";
  return text.size() > bytes ? text.substr(text.size() - bytes) : text;
}

int Fail(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

// --profile: one object scene, one profiled run; profile.txt is the run's profile tables.
int RunProfile(const std::string& synth, const std::string& solve, const std::string& out,
               const std::string& command) {
  const int size = FLAGS_size > 0 ? FLAGS_size : 256;
  const int views = FLAGS_views > 0 ? FLAGS_views : 48;
  const std::string scene = mgsr::JoinPath(out, "scene"), run = mgsr::JoinPath(out, "run");
  std::error_code ec;
  fs::remove_all(scene, ec);
  fs::remove_all(run, ec);
  const std::string synth_log = mgsr::JoinPath(out, "synth.log"),
                    log = mgsr::JoinPath(out, "run.log");
  std::printf("mgsr_bench --profile: %d px, %d views (dented object, specular, changing light)\n",
              size, views);
  std::fflush(stdout);
  const mgsr::ProgramResult made =
      mgsr::RunProgram({synth, "--output", scene, "--shape", "dented", "--seed", "11", "--mirror",
                        "0.3", "--width", std::to_string(size), "--height", std::to_string(size),
                        "--num_views", std::to_string(views)},
                       {}, synth_log);
  if (made.exit_code != 0) return Fail("mgsr_synth failed; see " + synth_log);
  std::vector<std::string> cmd = {
      solve,       "--workspace",  scene, "--output",           run, "--preset", "fast",
      "--profile", "--eval_every", "0",   "--checkpoint_every", "0"};
  if (FLAGS_profile_iterations > 0) {
    const std::string n = std::to_string(FLAGS_profile_iterations);
    cmd.insert(cmd.end(), {"--auto_stop=false", "--warmup_min_iterations", n,
                           "--warmup_max_iterations", n, "--mutual_iterations", n});
  }
  const std::vector<std::string> extra = Split(FLAGS_solve_flags, ' ');
  cmd.insert(cmd.end(), extra.begin(), extra.end());
  mgsr::Timer timer;
  const mgsr::ProgramResult pr = mgsr::RunProgram(cmd, {}, log, FLAGS_timeout);
  if (pr.exit_code != 0 || pr.timed_out)
    return Fail("mgsr_solve failed" + std::string(pr.timed_out ? " (timed out)" : "") + "; see " +
                log);
  // The profile tables are the lines from "profile, " to the rasterizer summary of each stage.
  std::string text;
  if (!mgsr::ReadFileToString(log, &text).ok()) return Fail(log + ": cannot read");
  std::string table;
  bool in_table = false;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("profile, ", 0) == 0) in_table = true;
    if (in_table) table += line + "\n";
    if (line.find("rasterizers (binning") != std::string::npos) in_table = false;
  }
  if (table.empty()) return Fail(log + ": the run printed no profile");
  const std::string header = "Made by `" + command + "` on " + Now() + ", commit `" +
                             Commit(mgsr::JoinPath(out, ".scratch.txt")) +
                             "`.\nMachine: " + Machine() + "; the run took " +
                             std::to_string(static_cast<int>(timer.ElapsedSeconds())) + " s.\n\n";
  const mgsr::Status s =
      mgsr::WriteStringToFileAtomic(mgsr::JoinPath(out, "profile.txt"), header + table);
  if (!s.ok()) return Fail(s.message());
  std::printf("%s%sprofile: %s/profile.txt, run: %s\n", header.c_str(), table.c_str(), out.c_str(),
              run.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  mgsr_tools::PreferShortOpenMpSpins(argv);
  std::string command = "mgsr_bench";
  for (int i = 1; i < argc; ++i) command += std::string(" ") + argv[i];
  mgsr_tools::ParseToolFlags(
      "mgsr_bench --output DIR [--quick] [--scenes a,b] [--methods x,y]",
      {{"What to run",
        {"scenes", "methods", "quick", "size", "views", "solve_flags", "timeout", "budgets",
         "workspace", "resume", "shared_data"}},
       {"Profile", {"profile", "profile_iterations"}},
       {"Output", {"output", "work", "title", "report_only", "nc_threshold"}}},
      &argc, &argv);
  if (FLAGS_output.empty()) return Fail("--output is required");
  if (!(FLAGS_timeout > 0)) return Fail("--timeout must be > 0");
  const std::string tools = ToolDir();
  const std::string synth = tools + "/mgsr_synth", solve = tools + "/mgsr_solve";
  if (mgsr::FindProgram(synth).empty() || mgsr::FindProgram(solve).empty())
    return Fail(tools + ": mgsr_synth and mgsr_solve must be next to mgsr_bench");
  if (FLAGS_profile) {
    const mgsr::Status made = mgsr::MakeDirectories(FLAGS_output);
    if (!made.ok()) return Fail(made.message());
    return RunProfile(synth, solve, FLAGS_output, command);
  }

  namespace b = mgsr::bench;
  b::ReportContext context;
  context.title = FLAGS_title;
  context.nc_threshold = FLAGS_nc_threshold;
  context.main_scene = "main";
  if (!FLAGS_workspace.empty()) {
    if (!fs::is_directory(FLAGS_workspace))
      return Fail("--workspace " + FLAGS_workspace + ": not a folder");
    b::SceneSpec external;
    external.name = fs::path(FLAGS_workspace).lexically_normal().filename().string();
    if (external.name.empty())
      external.name =
          fs::path(FLAGS_workspace).lexically_normal().parent_path().filename().string();
    external.stresses = "the workspace " + FLAGS_workspace;
    context.scenes.push_back(external);
    context.main_scene = external.name;
  } else {
    // The quality-size study runs on the main scene unless --scenes says otherwise.
    const std::string scenes =
        FLAGS_scenes.empty() && !FLAGS_budgets.empty() ? "main" : FLAGS_scenes;
    for (const b::SceneSpec& s : b::Scenes(FLAGS_quick)) {
      if (Selected(scenes, s.name)) context.scenes.push_back(s);
    }
  }
  if (!FLAGS_budgets.empty()) {
    const mgsr::Status parsed = b::BudgetMethods(FLAGS_budgets, &context.methods);
    if (!parsed.ok()) return Fail(parsed.message());
    context.budget_study = true;
  } else {
    for (const b::MethodSpec& m : b::Methods(FLAGS_quick)) {
      if (Selected(FLAGS_methods, m.name)) context.methods.push_back(m);
    }
  }
  if (context.scenes.empty()) return Fail("--scenes: no scene of the suite is selected");
  if (context.methods.empty()) return Fail("--methods: no method of the suite is selected");
  const int size = FLAGS_size > 0 ? FLAGS_size : (FLAGS_quick ? 48 : 64);
  const int views = FLAGS_views > 0 ? FLAGS_views : (FLAGS_quick ? 16 : 32);
  const std::vector<std::string> extra = Split(FLAGS_solve_flags, ' ');

  const std::string out = FLAGS_output;
  const std::string work = FLAGS_work.empty() ? out : FLAGS_work;
  mgsr::Status s = mgsr::MakeDirectories(out);
  if (s.ok()) s = mgsr::MakeDirectories(work);
  if (!s.ok()) return Fail(s.message());
  context.command = command;
  if (FLAGS_report_only) {
    b::ReportContext saved = context;
    s = b::ReadReportContext(mgsr::JoinPath(out, "context.json"), &saved);
    std::vector<b::RunRecord> runs;
    if (s.ok()) s = b::ReadResultsCsv(mgsr::JoinPath(out, "results.csv"), work, &runs);
    if (!s.ok()) return Fail(s.message());
    saved.rebuilt = Now();
    s = b::WriteReport(out, saved, runs);
    if (!s.ok()) return Fail(s.message());
    std::printf("mgsr_bench: report rebuilt from %zu runs: %s/README.md\n", runs.size(),
                out.c_str());
    return 0;
  }
  const std::string scratch = mgsr::JoinPath(out, ".scratch.txt");
  context.commit = Commit(scratch);
  context.date = Now();
  context.machine = Machine();
  const char* omp = std::getenv("OMP_NUM_THREADS");
  context.threads =
      omp != nullptr && std::atoi(omp) > 0 ? std::atoi(omp) : std::thread::hardware_concurrency();

  int total_runs = 0;
  for (const b::SceneSpec& sc : context.scenes) {
    for (const b::MethodSpec& m : context.methods) total_runs += b::Covers(m, sc, "main");
  }
  bool own_sizes = false;  // scenes with a size of their own (the detailed shapes)
  for (const b::SceneSpec& sc : context.scenes) own_sizes |= FLAGS_size == 0 && sc.size > 0;
  const std::string scene_size = FLAGS_workspace.empty()
                                     ? std::to_string(size) + " px" +
                                           (own_sizes ? " (or the scene's own size)" : "") + ", " +
                                           std::to_string(views) + " views"
                                     : "the workspace's own images";
  std::printf("mgsr_bench: %zu scenes, %zu methods, %d runs, %s\n", context.scenes.size(),
              context.methods.size(), total_runs, scene_size.c_str());
  std::fflush(stdout);

  std::vector<b::RunRecord> runs;
  std::error_code ec;
  int done = 0;
  mgsr::Timer all;
  for (const b::SceneSpec& sc : context.scenes) {
    // Scenes are generated afresh (seeded: a run kept by --resume saw the same images).
    const bool external = !FLAGS_workspace.empty();  // then it is the only scene
    const std::string scene_dir = external ? fs::absolute(FLAGS_workspace).string()
                                           : mgsr::JoinPath(work, "scenes/" + sc.name);
    // A scene's own size (detailed shapes) unless --size says otherwise.
    const int own_size = FLAGS_size == 0 && sc.size > 0 ? sc.size : size;
    std::vector<std::string> scene_args = sc.synth_args;
    bool missing = false;
    for (std::string& a : scene_args) {
      if (a.rfind(b::kSharedDataPrefix, 0) != 0) continue;
      a = mgsr::JoinPath(FLAGS_shared_data, a.substr(std::string(b::kSharedDataPrefix).size()));
      if (!mgsr::FileExists(a)) {
        std::printf("mgsr_bench: skipping scene %s: %s not found\n", sc.name.c_str(), a.c_str());
        missing = true;
      }
    }
    if (missing && !external) continue;
    if (!external) fs::remove_all(scene_dir, ec);
    std::vector<std::string> args = {synth,
                                     "--output",
                                     scene_dir,
                                     "--width",
                                     std::to_string(own_size),
                                     "--height",
                                     std::to_string(own_size),
                                     "--num_views",
                                     std::to_string(sc.num_views > 0 ? sc.num_views : views),
                                     "--seed",
                                     "7"};
    args.insert(args.end(), scene_args.begin(), scene_args.end());
    s = mgsr::MakeDirectories(mgsr::JoinPath(work, "runs/" + sc.name));
    if (!s.ok()) return Fail(s.message());
    const std::string synth_log = mgsr::JoinPath(work, "runs/" + sc.name + "/synth.log");
    fs::remove(synth_log, ec);
    if (!external) {
      const mgsr::ProgramResult made = mgsr::RunProgram(args, {}, synth_log);
      if (made.exit_code != 0)
        return Fail("mgsr_synth failed for scene " + sc.name + "; see " + synth_log);
    }

    for (const b::MethodSpec& m : context.methods) {
      if (!b::Covers(m, sc, "main")) continue;
      b::RunRecord r;
      r.scene = sc.name;
      r.method = m.name;
      r.run_dir = mgsr::JoinPath(work, "runs/" + sc.name + "/" + m.name);
      const std::string log = r.run_dir + ".log";
      std::vector<std::string> cmd = {solve,     "--workspace", scene_dir, "--output",
                                      r.run_dir, "--preset",    "fast",    "--eval_every",
                                      "0",       "--log_every", "100000",  "--checkpoint_every",
                                      "0"};
      cmd.insert(cmd.end(), m.solve_args.begin(), m.solve_args.end());
      cmd.insert(cmd.end(), extra.begin(), extra.end());
      std::printf("[%d/%d] %s / %s ...", ++done, total_runs, sc.name.c_str(), m.name.c_str());
      std::fflush(stdout);
      const bool kept =
          FLAGS_resume && b::FinishedEarlier(r.run_dir, cmd, context.commit, &r.wall_seconds);
      if (kept) {
        b::ReadRunResult(0, 0, false, FLAGS_timeout, Tail(log, 4000), FLAGS_nc_threshold, &r);
      } else {
        b::ForgetRun(r.run_dir);
        fs::remove_all(r.run_dir, ec);
        fs::remove(log, ec);
        mgsr::Timer timer;
        const mgsr::ProgramResult pr = mgsr::RunProgram(cmd, {}, log, FLAGS_timeout);
        r.wall_seconds = timer.ElapsedSeconds();
        b::ReadRunResult(pr.exit_code, pr.signal, pr.timed_out, FLAGS_timeout, Tail(log, 4000),
                         FLAGS_nc_threshold, &r);
        if (r.ok) s = b::MarkRunFinished(r.run_dir, cmd, context.commit, r.wall_seconds);
        if (!s.ok()) return Fail(s.message());
      }
      if (r.ok) {
        std::printf(" %s, %.0f s: NC x100 %.2f, PSNR %.2f (aligned %.2f)\n",
                    kept ? "kept from the earlier run" : "ok", r.wall_seconds, 100 * r.nc, r.psnr,
                    r.psnr_aligned);
      } else {
        std::printf(" FAILED (%s), %.0f s\n", r.failure.c_str(), r.wall_seconds);
      }
      if (done < total_runs)
        std::printf("%s\n",
                    mgsr::ProgressLine("mgsr_bench", "runs", done, total_runs, all.ElapsedSeconds())
                        .c_str());
      std::fflush(stdout);
      runs.push_back(std::move(r));
    }
  }
  s = b::WriteReport(out, context, runs);
  if (!s.ok()) return Fail(s.message());
  int failed = 0;
  for (const b::RunRecord& r : runs) failed += !r.ok;
  std::printf("mgsr_bench: %zu runs (%d failed) in %.0f s; report: %s/README.md\n", runs.size(),
              failed, all.ElapsedSeconds(), out.c_str());
  return 0;
}
