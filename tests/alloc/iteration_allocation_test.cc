// A training iteration allocates nothing once the first ones have sized every buffer (#20): the
// global operator new is replaced by a counting one (this file is its own test program, so no
// other test runs under it) and a callback reads the count at every iteration boundary. The call
// stacks of the first allocations of the late iterations are kept and printed when the test fails
// (such an allocation can depend on thread scheduling and show only on a loaded machine).
#include <execinfo.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <new>
#include <string>
#include <vector>

#include "solvers/mutual_boosted_solver.h"
#include "test_util.h"

namespace {
std::atomic<int64_t> g_allocations{0};

// The call stacks of the first allocations made in iterations that must not allocate (the
// counter drops those recorded in the others). Fixed storage: recording must not allocate through
// operator new.
constexpr int kStacks = 4, kFrames = 24;
void* g_stack[kStacks][kFrames];
int g_stack_depth[kStacks];
std::atomic<int> g_stacks{0};

void* CountedAlloc(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  const int slot = g_stacks.fetch_add(1);
  if (slot < kStacks) g_stack_depth[slot] = backtrace(g_stack[slot], kFrames);
  void* p = std::malloc(size == 0 ? 1 : size);
  if (p == nullptr) throw std::bad_alloc();
  return p;
}

void PrintKeptStacks() {
  const int kept = std::min(g_stacks.load(), kStacks);
  for (int i = 0; i < kept; ++i) {
    const char line[] =
        "---- allocation in a steady iteration (decode: addr2line -fCe <program> <+offsets>):\n";
    (void)!write(2, line, sizeof(line) - 1);
    backtrace_symbols_fd(g_stack[i], g_stack_depth[i], 2);
  }
}
}  // namespace

void* operator new(std::size_t size) { return CountedAlloc(size); }
void* operator new[](std::size_t size) { return CountedAlloc(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return CountedAlloc(size);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return CountedAlloc(size);
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace mgsr {
namespace {

// Records the allocations of each iteration (from one iteration boundary to the next), and keeps
// the call stacks of allocations only in iterations that must not allocate.
class AllocationCounter : public IterationCallback {
 public:
  // Reserved up front: the counter's own bookkeeping must not count.
  AllocationCounter() {
    warmup.reserve(1000);
    mutual.reserve(1000);
  }
  CallbackReturnType operator()(const IterationInfo&) override {
    return CallbackReturnType::kContinue;
  }
  CallbackReturnType OnIterationEnd(const MutualBoostedSolver&, Stage stage, int) override {
    const int64_t now = g_allocations.load();
    bool late = false;  // the iteration that just ended must not have allocated
    if (last_ >= 0) {
      std::vector<int64_t>& per_iteration = stage == Stage::kWarmup ? warmup : mutual;
      per_iteration.push_back(now - last_);
      late = IsLate(stage, per_iteration.size() - 1);
    }
    if (!late) g_stacks = kept_;  // drop the stacks it recorded
    kept_ = std::min(g_stacks.load(), kStacks);
    last_ = g_allocations.load();
    return CallbackReturnType::kContinue;
  }
  // Whether warmup[i] / mutual[i] must be 0: from warm-up iteration 76 and mutual iteration 10
  // on (warmup[i] is iteration i + 2, from one iteration's end to the next's; mutual[0] holds
  // the switch of stages and the first mutual iteration).
  static bool IsLate(Stage stage, size_t i) { return stage == Stage::kWarmup ? i >= 74 : i >= 9; }
  std::vector<int64_t> warmup, mutual;

 private:
  int64_t last_ = -1;
  int kept_ = 0;  // stacks kept from late iterations
};

// Both density strategies (reference: the library's default; mcmc: mgsr_solve's), the auto-stop
// window on, exposure compensation and the mutual stage as the fast preset runs them; density
// control's events resize the models, so they are scheduled after the end. Buffers that follow
// the model's screen footprint grow geometrically during the first iterations; from warm-up
// iteration 76 and mutual iteration 10 on, nothing may be allocated.
class IterationAllocationTest : public ::testing::TestWithParam<std::string> {};

TEST_P(IterationAllocationTest, SteadyIterationsAllocateNothing) {
  const Scene scene = testing::TinySolverScene(testing::ScratchDir("_" + GetParam()));
  SolverOptions o;
  SolverOptions::FromPreset("fast", &o);
  o.warmup_min_iterations = 0;
  o.warmup_max_iterations = 150;
  o.mutual_iterations = 60;
  o.auto_stop = true;
  o.auto_stop_window = 20;
  o.auto_stop_range = 0;  // never flat: the window runs, the warm-up does not stop
  o.schedule_2d = {1000, 1000, 100, 100000, 0.05f};
  o.schedule_3d = {1000, 1000, 100, 100000, 0.005f};
  o.sh_interval = 1000;
  o.density = GetParam();
  if (o.density == "mcmc") o.max_gaussians = o.max_surfels = 100000;
  ASSERT_TRUE(o.Validate().ok());
  MutualBoostedSolver solver(o, scene);
  AllocationCounter counter;
  solver.AddCallback(&counter);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  ASSERT_EQ(counter.warmup.size(), 149u);
  ASSERT_GE(counter.mutual.size(), 59u);
  int64_t late = 0;
  for (size_t i = 0; i < counter.warmup.size(); ++i)
    if (AllocationCounter::IsLate(Stage::kWarmup, i)) late += counter.warmup[i];
  for (size_t i = 0; i < counter.mutual.size(); ++i)
    if (AllocationCounter::IsLate(Stage::kMutual, i)) late += counter.mutual[i];
  std::string per_iteration;
  for (int64_t a : counter.warmup) per_iteration += std::to_string(a) + " ";
  per_iteration += "| ";
  for (int64_t a : counter.mutual) per_iteration += std::to_string(a) + " ";
  EXPECT_EQ(late, 0) << "allocations per iteration (warm-up | mutual): " << per_iteration;
  if (late != 0) PrintKeptStacks();
  // The count is real: the first iterations do allocate (they size every buffer).
  EXPECT_GT(counter.warmup[0] + counter.mutual[0], 0);
}

INSTANTIATE_TEST_SUITE_P(Density, IterationAllocationTest, ::testing::Values("reference", "mcmc"));

}  // namespace
}  // namespace mgsr
