// The fast preset shortened for solver tests: the given stage lengths, no minimum warm-up and no
// auto-stop (a test says how many steps it wants); each test then sets its own schedules.
#pragma once

#include "solvers/solver_options.h"

namespace mgsr {
namespace testing {

inline SolverOptions ShortFastOptions(int warmup_iterations, int mutual_iterations) {
  SolverOptions o;
  SolverOptions::FromPreset("fast", &o);
  o.warmup_min_iterations = 0;
  o.warmup_max_iterations = warmup_iterations;
  o.mutual_iterations = mutual_iterations;
  o.auto_stop = false;
  return o;
}

}  // namespace testing
}  // namespace mgsr
