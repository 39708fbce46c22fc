// OpenMP threads that do not spin while they wait, unless the user chose a policy. libgomp's
// default keeps a waiting thread spinning for a while at every barrier; on a machine where another
// process holds a core (a laptop with a browser, a CI runner, a cluster node shared with other
// ranks), the spinning thread takes the time slice the working one needs, and two threads run
// slower than one (docs/performance.md, "Shared machines"). libgomp reads its wait settings once,
// when it is loaded, before main: so a tool sets them and runs itself again, with the same
// arguments, before it does anything else.
#pragma once

#include <unistd.h>

#include <cstdlib>

namespace mgsr_tools {

// The wait policy the tools run under unless OMP_WAIT_POLICY or GOMP_SPINCOUNT is set.
constexpr const char* kOpenMpWaitPolicy = "PASSIVE";

// Call first in main. Returns only when the policy is in effect (or cannot be set: then as before).
inline void PreferPassiveOpenMpWaits(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr || std::getenv("GOMP_SPINCOUNT") != nullptr ||
      std::getenv("MGSR_OPENMP_WAIT_SET") != nullptr)
    return;
  setenv("OMP_WAIT_POLICY", kOpenMpWaitPolicy, 1);
  setenv("MGSR_OPENMP_WAIT_SET", "1", 1);  // never twice, even if the policy is unset again
  execv("/proc/self/exe", argv);
  // No /proc (or exec refused): run with libgomp's defaults.
}

}  // namespace mgsr_tools
