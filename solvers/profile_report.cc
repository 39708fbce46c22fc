#include "solvers/profile_report.h"

#include <algorithm>
#include <cstdio>
#include <map>

namespace mgsr {
namespace {

const char* StageKey(Stage s) { return s == Stage::kWarmup ? "warmup" : "mutual"; }

// Column of a context: 0 = 2DGS, 1 = 3DGS, 2 = solver (any other label).
int Column(const std::string& context) {
  if (context == BranchLabel(Branch::kSurfels2D)) return 0;
  if (context == BranchLabel(Branch::kGaussians3D)) return 1;
  return 2;
}

struct Row {
  std::string name;
  double ms[3] = {0, 0, 0};
};

// Rows in the order scopes were first seen, ms per iteration per column.
std::vector<Row> Rows(const StageProfile& p) {
  std::vector<Row> rows;
  const double per = p.iterations > 0 ? 1e3 / p.iterations : 0;
  for (const ProfileEntry& e : p.entries) {
    auto it =
        std::find_if(rows.begin(), rows.end(), [&](const Row& r) { return r.name == e.name; });
    if (it == rows.end()) {
      rows.push_back(Row{e.name, {0, 0, 0}});
      it = rows.end() - 1;
    }
    it->ms[Column(e.context)] += e.seconds * per;
  }
  return rows;
}

double Sum(const Row& r) { return r.ms[0] + r.ms[1] + r.ms[2]; }

std::string Cell(double ms) {
  if (ms == 0) return "-";
  char b[32];
  std::snprintf(b, sizeof(b), "%.2f", ms);
  return b;
}

}  // namespace

bool IsRasterizerScope(const std::string& name) {
  return name == "binning" || name == "raster forward" || name == "raster backward";
}

bool IsCallbackScope(const std::string& name) { return name == "callbacks"; }

std::string FormatProfile(const std::vector<StageProfile>& profile) {
  std::string out;
  char line[256];
  for (const StageProfile& p : profile) {
    const double iteration_ms = p.iterations > 0 ? 1e3 * p.seconds / p.iterations : 0;
    std::snprintf(line, sizeof(line), "profile, %s: %d iterations, %.2f ms per iteration\n",
                  p.stage == Stage::kWarmup ? "warm-up" : "mutual stage", p.iterations,
                  iteration_ms);
    out += line;
    std::snprintf(line, sizeof(line), "  %-26s %9s %9s %9s %9s %7s\n", "ms per iteration", "2DGS",
                  "3DGS", "solver", "total", "share");
    out += line;
    double named = 0, raster = 0, callbacks = 0;
    for (const Row& r : Rows(p)) {
      const double total = Sum(r);
      named += total;
      if (IsRasterizerScope(r.name)) raster += total;
      if (IsCallbackScope(r.name)) callbacks += total;
      std::snprintf(line, sizeof(line), "  %-26s %9s %9s %9s %9.2f %6.1f%%\n", r.name.c_str(),
                    Cell(r.ms[0]).c_str(), Cell(r.ms[1]).c_str(), Cell(r.ms[2]).c_str(), total,
                    iteration_ms > 0 ? 100 * total / iteration_ms : 0.0);
      out += line;
    }
    const double other = std::max(0.0, iteration_ms - named);
    std::snprintf(line, sizeof(line), "  %-26s %9s %9s %9s %9.2f %6.1f%%\n", "other (no scope)", "",
                  "", "", other, iteration_ms > 0 ? 100 * other / iteration_ms : 0.0);
    out += line;
    const double rest = iteration_ms - raster;
    std::snprintf(line, sizeof(line),
                  "  rasterizers (binning, forward, backward) %.2f ms, the rest %.2f ms (%.1f%% of "
                  "the iteration, %.2fx the rasterizers)\n",
                  raster, rest, iteration_ms > 0 ? 100 * rest / iteration_ms : 0.0,
                  raster > 0 ? rest / raster : 0.0);
    out += line;
    // The caller's hooks are not the training's work (a run without ground truth has no
    // diagnostics): the share without them, beside the plain one.
    if (callbacks > 0) {
      const double training = iteration_ms - callbacks;
      std::snprintf(
          line, sizeof(line),
          "  without the callbacks (%.2f ms: progress lines, diagnostics, checkpoints) the "
          "rest %.2f ms (%.1f%% of the training iteration)\n",
          callbacks, rest - callbacks, training > 0 ? 100 * (rest - callbacks) / training : 0.0);
      out += line;
    }
  }
  return out;
}

nlohmann::json ProfileToJson(const std::vector<StageProfile>& profile) {
  nlohmann::json j = nlohmann::json::object();
  for (const StageProfile& p : profile) {
    const double per = p.iterations > 0 ? 1e3 / p.iterations : 0;
    nlohmann::json scopes = nlohmann::json::array();
    double raster = 0;
    for (const ProfileEntry& e : p.entries) {
      const std::string branch = Column(e.context) == 2 ? "solver" : e.context;
      scopes.push_back({{"name", e.name},
                        {"branch", branch},
                        {"ms_per_iteration", e.seconds * per},
                        {"calls", e.calls}});
      if (IsRasterizerScope(e.name)) raster += e.seconds;
    }
    j[StageKey(p.stage)] = {{"iterations", p.iterations},
                            {"seconds", p.seconds},
                            {"ms_per_iteration", p.seconds * per},
                            {"rasterizer_share", p.seconds > 0 ? raster / p.seconds : 0.0},
                            {"scopes", scopes}};
  }
  return j;
}

}  // namespace mgsr
