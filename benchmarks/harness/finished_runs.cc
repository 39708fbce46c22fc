#include "benchmarks/harness/finished_runs.h"

#include <filesystem>
#include <nlohmann/json.hpp>

#include "mgsr/io/file_util.h"

namespace mgsr::bench {
namespace {

std::string MarkerPath(const std::string& run_dir) { return run_dir + ".done"; }

bool Reproducible(const std::string& commit) {
  return !commit.empty() && commit != "unknown" && commit.find("uncommitted") == std::string::npos;
}

}  // namespace

Status MarkRunFinished(const std::string& run_dir, const std::vector<std::string>& command,
                       const std::string& commit, double wall_seconds) {
  nlohmann::json j;
  j["command"] = command;
  j["commit"] = commit;
  j["wall_seconds"] = wall_seconds;
  return WriteStringToFileAtomic(MarkerPath(run_dir), j.dump(1) + "\n");
}

bool FinishedEarlier(const std::string& run_dir, const std::vector<std::string>& command,
                     const std::string& commit, double* wall_seconds) {
  if (!Reproducible(commit) || !FileExists(JoinPath(run_dir, "metrics.json"))) return false;
  std::string text;
  if (!ReadFileToString(MarkerPath(run_dir), &text).ok()) return false;
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return false;
  const auto c = j.find("command"), k = j.find("commit"), w = j.find("wall_seconds");
  if (c == j.end() || k == j.end() || w == j.end() || !c->is_array() || !k->is_string() ||
      !w->is_number())
    return false;
  if (c->size() != command.size() || k->get<std::string>() != commit) return false;
  for (size_t i = 0; i < command.size(); ++i) {
    if (!(*c)[i].is_string() || (*c)[i].get<std::string>() != command[i]) return false;
  }
  *wall_seconds = w->get<double>();
  return true;
}

void ForgetRun(const std::string& run_dir) {
  std::error_code ec;
  std::filesystem::remove(MarkerPath(run_dir), ec);
}

}  // namespace mgsr::bench
