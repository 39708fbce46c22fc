// The per-stage profile of a solve (SolveSummary::profile, mgsr_solve --profile) as a table for the
// log and as JSON for metrics.json: milliseconds per iteration per scope and branch, what no scope
// names ("other"), and the rasterizers' share.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "solvers/mutual_boosted_solver.h"

namespace mgsr {

// The scopes that are the rasterizers' work (tile binning, forward and backward rasterization);
// everything else of an iteration is what issue #20 calls "the rest".
bool IsRasterizerScope(const std::string& name);
// The scope of the solver's callbacks (the caller's progress lines, diagnostics and checkpoints):
// part of the rest, reported apart as well.
bool IsCallbackScope(const std::string& name);

// One table per stage: rows are scopes (in the order first seen), columns the 2DGS branch, the
// 3DGS branch, the solver (scopes outside any branch) and their sum, in ms per iteration.
std::string FormatProfile(const std::vector<StageProfile>& profile);

// {"warmup": {"iterations", "seconds", "ms_per_iteration", "rasterizer_share",
//  "scopes": [{"name", "branch", "ms_per_iteration", "calls"}...]}, "mutual": {...}}
nlohmann::json ProfileToJson(const std::vector<StageProfile>& profile);

}  // namespace mgsr
