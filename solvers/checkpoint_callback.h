// CheckpointCallback: writes the solver's checkpoint every N iterations, at an iteration boundary
// (IterationCallback::OnIterationEnd), so a run killed at any moment loses at most N iterations
// and --resume continues it exactly. An optional `after_save` runs after each write (mgsr_solve
// flushes its log there, so the log never runs behind the checkpoint). A failed write aborts the
// run; status() then says why.
#pragma once

#include <functional>
#include <string>

#include "mgsr/core/status.h"
#include "solvers/mutual_boosted_solver.h"

namespace mgsr {

class CheckpointCallback : public IterationCallback {
 public:
  CheckpointCallback(std::string path, int every, std::function<Status()> after_save = nullptr)
      : path_(std::move(path)), every_(every), after_save_(std::move(after_save)) {}

  CallbackReturnType operator()(const IterationInfo&) override {
    return CallbackReturnType::kContinue;
  }
  CallbackReturnType OnIterationEnd(const MutualBoostedSolver& solver, Stage stage,
                                    int iteration) override;

  const Status& status() const { return status_; }
  int checkpoints_written() const { return written_; }

 private:
  std::string path_;
  int every_;
  std::function<Status()> after_save_;
  int count_ = 0, written_ = 0;
  Status status_;
};

}  // namespace mgsr
