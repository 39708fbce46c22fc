// The benchmark suite: synthetic scenes that each stress one thing, and the methods and ablations
// run on them, all as command-line arguments of mgsr_synth and mgsr_solve (one binary each, no
// copies of the loop).
#pragma once

#include <string>
#include <vector>

#include "mgsr/core/status.h"

namespace mgsr::bench {

struct SceneSpec {
  std::string name;
  std::string stresses;                 // one line for the report
  std::vector<std::string> synth_args;  // mgsr_synth flags (size and views added by the runner)
  int num_views = 0;                    // 0: the suite's default
  bool varying_light = true;
  // Image size (width and height); 0: the suite's default. Detailed shapes need more pixels than
  // the suite's small default to show their detail at all.
  int size = 0;
};

// In synth_args, this prefix stands for the shared data folder (mgsr_bench --shared_data); a scene
// whose file there is missing is skipped with a note.
constexpr const char* kSharedDataPrefix = "{shared}/";

// Which scenes a method runs on.
enum class Coverage { kAll, kMainScene, kVaryingLight };

struct MethodSpec {
  std::string name;
  std::string description;
  std::vector<std::string> solve_args;  // mgsr_solve flags
  Coverage coverage = Coverage::kAll;
};

// Scenes, in run order. The first "main" scene is the main case (specular, varying light).
std::vector<SceneSpec> Scenes(bool quick);
// The four methods of the comparison, then (full suite only) the ablations and the exposure
// variant, which run on fewer scenes (see Coverage).
std::vector<MethodSpec> Methods(bool quick);
// The quality-size study (mgsr_bench --budgets): the MCMC strategy at each budget of a
// comma-separated list (a count per branch: "5000", "5k", or "auto" for the scene's own rule),
// named "mcmc-5k", "mcmc-auto", ..., then the reference strategy at its scene-sized bound
// ("reference"), the point the curve is read against. An empty list, a repeated or malformed entry
// is an error naming it.
Status BudgetMethods(const std::string& list, std::vector<MethodSpec>* methods);

bool Covers(const MethodSpec& method, const SceneSpec& scene, const std::string& main_scene);

}  // namespace mgsr::bench
