#pragma once
// Which harness runs have already finished, so that `mgsr_bench --resume` continues a stopped
// study (a full report is an hour of runs) instead of starting it over. A run counts as finished
// when a marker beside its folder (`<run_dir>.done`) records the exact mgsr_solve command line and
// the commit it ran at, and the run's metrics.json exists; any difference reruns it, so a resumed
// report never mixes code versions or settings.
#include <string>
#include <vector>

#include "mgsr/core/status.h"

namespace mgsr::bench {

// Records that the run in `run_dir` finished: its command, the commit and its wall time.
Status MarkRunFinished(const std::string& run_dir, const std::vector<std::string>& command,
                       const std::string& commit, double wall_seconds);

// True when `run_dir` finished with exactly this command at this commit (and its metrics.json is
// there); then `*wall_seconds` is the time it took. A commit that says "uncommitted changes" never
// matches: such a tree cannot be told from the next edit.
bool FinishedEarlier(const std::string& run_dir, const std::vector<std::string>& command,
                     const std::string& commit, double* wall_seconds);

// Removes the marker (a run about to be redone).
void ForgetRun(const std::string& run_dir);

}  // namespace mgsr::bench
