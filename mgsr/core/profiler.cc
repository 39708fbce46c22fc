#include "mgsr/core/profiler.h"

#include <atomic>
#include <chrono>
#include <cstring>
#include <string>
#include <thread>

namespace mgsr {
namespace {

struct Slot {
  std::string context, name;  // copies: a scope's name need only live as long as the scope
  int64_t ns;
  int64_t calls;
};

// Only the recording thread touches these (see the header), so no lock is needed; the flag and
// the thread id are atomics so that other threads can test them.
std::atomic<bool> g_enabled{false};
std::atomic<std::thread::id> g_thread{};
std::vector<Slot>& Slots() {
  static std::vector<Slot> slots;
  return slots;
}
thread_local const char* t_context = "";
thread_local ProfileScope* t_innermost = nullptr;

bool Recording() {
  return g_enabled.load(std::memory_order_relaxed) &&
         g_thread.load(std::memory_order_relaxed) == std::this_thread::get_id();
}

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void Charge(const char* context, const char* name, int64_t ns) {
  // A few dozen stages at most: a linear search (allocates only when a stage is first seen).
  std::vector<Slot>& slots = Slots();
  for (Slot& s : slots) {
    if (std::strcmp(s.name.c_str(), name) == 0 && std::strcmp(s.context.c_str(), context) == 0) {
      s.ns += ns;
      ++s.calls;
      return;
    }
  }
  slots.push_back({std::string(context), std::string(name), ns, 1});
}

}  // namespace

void Profiler::SetEnabled(bool enabled) {
  if (enabled) {
    Slots().reserve(64);  // so that recording does not allocate after the first stages
    g_thread.store(std::this_thread::get_id());
  }
  g_enabled.store(enabled);
}

bool Profiler::Enabled() { return g_enabled.load(std::memory_order_relaxed); }

std::vector<ProfileEntry> Profiler::Take() {
  std::vector<ProfileEntry> out;
  for (const Slot& s : Slots()) out.push_back({s.context, s.name, s.ns * 1e-9, s.calls});
  Slots().clear();
  return out;
}

ProfileContext::ProfileContext(const char* label) {
  if (!Recording()) return;
  active_ = true;
  previous_ = t_context;
  t_context = label;
}

ProfileContext::~ProfileContext() {
  if (active_) t_context = previous_;
}

ProfileScope::ProfileScope(const char* name) {
  if (!Recording()) return;
  name_ = name;
  context_ = t_context;
  parent_ = t_innermost;
  t_innermost = this;
  start_ns_ = NowNs();
}

ProfileScope::~ProfileScope() {
  if (name_ == nullptr) return;
  const int64_t total = NowNs() - start_ns_;
  Charge(context_, name_, total - children_ns_);
  if (parent_ != nullptr) parent_->children_ns_ += total;
  t_innermost = parent_;
}

}  // namespace mgsr
