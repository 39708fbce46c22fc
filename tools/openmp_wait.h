// OpenMP threads that spin only briefly while they wait, unless the user chose a policy.
// libgomp's default keeps a waiting thread spinning for up to 300,000 rounds at every barrier; on
// a machine where another process holds a core (a laptop with a browser, a CI runner, a cluster
// node shared with other ranks), the spinning thread takes the time slice the working one needs,
// and two threads run slower than one. Not spinning at all (OMP_WAIT_POLICY=PASSIVE) costs the
// idle machine a futex wake-up at every barrier. A few hundred rounds keep both: measured on the
// 128 px fast run, 2 threads against 1 (docs/performance.md, "Shared machines"). libgomp reads
// these settings once, when it is loaded, before main: so a tool sets them and runs itself again,
// with the same arguments, before it does anything else.
#pragma once

#include <unistd.h>

#include <cstdlib>

namespace mgsr_tools {

// Spin rounds before a waiting thread sleeps, unless OMP_WAIT_POLICY or GOMP_SPINCOUNT is set.
constexpr const char* kOpenMpSpinCount = "300";

// Call first in main. Returns only when the setting is in effect (or cannot be made: then the
// tool runs with libgomp's defaults).
inline void PreferShortOpenMpSpins(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") != nullptr || std::getenv("GOMP_SPINCOUNT") != nullptr ||
      std::getenv("MGSR_OPENMP_WAIT_SET") != nullptr)
    return;
  setenv("GOMP_SPINCOUNT", kOpenMpSpinCount, 1);
  setenv("MGSR_OPENMP_WAIT_SET", "1", 1);  // never twice, even if the setting is removed again
  execv("/proc/self/exe", argv);
  // No /proc (or exec refused): run with libgomp's defaults.
}

}  // namespace mgsr_tools
