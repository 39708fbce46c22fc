// Where a training run's time goes: wall time per named stage (projection, binning, raster forward,
// losses, Adam, ...), per branch, for `mgsr_solve --profile` and `mgsr_bench --profile`.
//
// Off by default, when a scope costs one relaxed load of a flag. Scopes are opened around serial
// regions of the thread that drives training (they may run OpenMP loops inside); scopes opened on
// other threads while profiling is on are ignored. Time is charged exclusively: a nested scope's
// time belongs to it, not to the scope around it (the exposure step inside the loss evaluation is
// "exposure", not "losses"). The branch a scope's time belongs to is the innermost
// ProfileContext's label ("2DGS", "3DGS"), or "" outside any.
//
//   ProfileContext branch("3DGS");
//   { ProfileScope s("raster forward"); Rasterize(...); }
//
// A scope keeps its name and label as pointers (it never allocates); they must live as long as
// the scope. The profiler copies them when a stage is first seen.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace mgsr {

struct ProfileEntry {
  std::string context;  // the ProfileContext label ("" outside any)
  std::string name;     // the scope's name
  double seconds = 0;   // exclusive wall time
  int64_t calls = 0;
};

class Profiler {
 public:
  // Switches recording on or off for the whole process; the thread that switches it on is the
  // one whose scopes count.
  static void SetEnabled(bool enabled);
  static bool Enabled();
  // What was recorded since the last Take (in the order stages were first seen), and clears it.
  static std::vector<ProfileEntry> Take();
};

// Labels the scopes opened while it lives (innermost wins).
class ProfileContext {
 public:
  explicit ProfileContext(const char* label);
  ~ProfileContext();
  ProfileContext(const ProfileContext&) = delete;
  ProfileContext& operator=(const ProfileContext&) = delete;

 private:
  const char* previous_ = nullptr;
  bool active_ = false;
};

class ProfileScope {
 public:
  explicit ProfileScope(const char* name);
  ~ProfileScope();
  ProfileScope(const ProfileScope&) = delete;
  ProfileScope& operator=(const ProfileScope&) = delete;

 private:
  const char* name_ = nullptr;  // nullptr: not recording
  const char* context_ = nullptr;
  ProfileScope* parent_ = nullptr;
  int64_t start_ns_ = 0;
  int64_t children_ns_ = 0;
};

}  // namespace mgsr
