// The loss table: which loss terms each branch minimises in each stage, with what weight and from
// which iteration, as data (like a list of Ceres residual blocks, but built from the registry by
// name). The solver builds one Problem per branch and stage from it, once, and switches rows on
// and off by iteration. The default is the paper's table (PaperLossTable, from SolverOptions'
// scalar weights); a JSON file (--loss_config) overrides rows or adds new ones, so a new term that
// trains is one class, one registration line and one row:
//
//   {"losses": [
//     {"branch": "2d", "stage": "warmup", "name": "normal_consistency", "weight": 1.0},
//     {"branch": "2d", "stage": "both", "name": "my_term", "term": "my_registered_term",
//      "config": {"buffer": "depth"}, "weight": 0.1, "first_iteration": 500}
//   ]}
//
// A row is identified by (branch, stage, name); a config row with the identity of an existing row
// changes only the fields it gives, any other adds a row (then "term" and "weight" are required).
// "replace": true starts from an empty table instead of the default. "exposure": true puts the
// term behind the view's colour transform when exposure compensation is on (photometric terms on
// the colour against the photo).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mgsr/core/status.h"
#include "mgsr/loss/problem.h"

namespace mgsr {

struct SolverOptions;

enum class Stage { kWarmup, kMutual };
const char* StageName(Stage stage);     // "warmup" | "mutual"
const char* BranchName(Branch branch);  // "2d" | "3d"

struct LossSpec {
  Branch branch = Branch::kSurfels2D;
  Stage stage = Stage::kWarmup;
  std::string name;  // unique within (branch, stage); the log's label
  std::string term;  // LossRegistry name, or PriorRegistry name (solvers/primitive_prior.h)
  nlohmann::json config = nlohmann::json::object();
  double weight = 0;
  int first_iteration = 0;  // active from this iteration of the stage on (0 and 1: from the start)
  bool exposure = false;    // behind the view's colour transform when compensation is on
};

// The paper's table (method.md 1.3-1.7) with the options' weights and schedules. In the mutual
// stage the 2DGS branch's render loss is two rows (against the 3DGS transmitted image, and against
// the photo behind the view's colour transform), each weighted by w_2d.
std::vector<LossSpec> PaperLossTable(const SolverOptions& options);

// Every row's term exists in the registry and accepts its config, weights are finite and >= 0,
// names are unique within (branch, stage). Errors name the row.
Status CheckLossTable(const std::vector<LossSpec>& table);

// Applies a config object ({"replace": bool, "losses": [rows]}) to `table`; `source` names it in
// errors (the file).
Status ApplyLossConfig(const nlohmann::json& config, const std::string& source,
                       std::vector<LossSpec>* table);
// Reads a JSON file and applies it.
Status ApplyLossConfigFile(const std::string& path, std::vector<LossSpec>* table);

nlohmann::json LossSpecToJson(const LossSpec& spec);
nlohmann::json LossTableToJson(const std::vector<LossSpec>& table);
// "2d/warmup/normal_consistency": how errors and listings name a row.
std::string LossSpecId(const LossSpec& spec);

}  // namespace mgsr
