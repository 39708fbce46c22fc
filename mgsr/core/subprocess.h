// Running an external program (the `colmap` binary) without a shell: arguments are passed as they
// are, so paths with spaces or quotes need no escaping.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace mgsr {

// The absolute path of `program` (searched on PATH unless it contains a '/'); "" when there is no
// executable file by that name.
std::string FindProgram(const std::string& program);

struct ProgramResult {
  bool started = false;  // false: the program could not be executed
  int exit_code = -1;    // exit status; 128 + signal number when killed by a signal
  int signal = 0;        // the signal that ended it, 0 when it exited
  bool timed_out = false;
};

// Runs argv[0] (a path, as FindProgram gives) with the given arguments and extra environment
// entries ("NAME=value"), appending its stdout and stderr to `log_path`, and waits for it.
// With timeout_seconds > 0 the program is killed (SIGKILL) when it runs longer. `on_wait`, when
// given, is called about every half second while the program runs (e.g. to read its log for a
// progress line).
ProgramResult RunProgram(const std::vector<std::string>& argv,
                         const std::vector<std::string>& extra_env, const std::string& log_path,
                         double timeout_seconds = 0, const std::function<void()>& on_wait = {});

}  // namespace mgsr
