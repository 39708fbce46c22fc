#include "solvers/checkpoint_callback.h"

namespace mgsr {

CallbackReturnType CheckpointCallback::OnIterationEnd(const MutualBoostedSolver& solver, Stage,
                                                      int) {
  if (every_ <= 0 || ++count_ % every_ != 0) return CallbackReturnType::kContinue;
  status_ = solver.SaveCheckpoint(path_);
  if (status_.ok() && after_save_) status_ = after_save_();
  if (!status_.ok()) return CallbackReturnType::kAbort;
  ++written_;
  return CallbackReturnType::kContinue;
}

}  // namespace mgsr
