// A training iteration allocates nothing once the first ones have sized every buffer (#20): the
// global operator new is replaced by a counting one (this file is its own test program, so no
// other test runs under it) and a callback reads the count at every iteration boundary.
// MGSR_ALLOC_REPORT=1 prints a backtrace of the first allocations of the late iterations.
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
std::atomic<bool> g_report{false};
std::atomic<int> g_reported{0};

void* CountedAlloc(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (g_report.load(std::memory_order_relaxed) && g_reported.fetch_add(1) < 60) {
    void* frames[24];
    const int n = backtrace(frames, 24);
    const char line[] = "---- allocation in a steady iteration:\n";
    (void)!write(2, line, sizeof(line) - 1);
    backtrace_symbols_fd(frames, n, 2);
  }
  void* p = std::malloc(size == 0 ? 1 : size);
  if (p == nullptr) throw std::bad_alloc();
  return p;
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

// Records the allocations of each iteration (from one iteration boundary to the next).
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
  CallbackReturnType OnIterationEnd(const MutualBoostedSolver&, Stage stage,
                                    int iteration) override {
    const int64_t now = g_allocations.load();
    if (last_ >= 0) {
      (stage == Stage::kWarmup ? warmup : mutual).push_back(now - last_);
      if (stage == report_stage && iteration == report_from) g_report = true;
    }
    last_ = g_allocations.load();
    return CallbackReturnType::kContinue;
  }
  std::vector<int64_t> warmup, mutual;
  Stage report_stage = Stage::kWarmup;
  int report_from = -1;

 private:
  int64_t last_ = -1;
};

// Both density strategies (reference: the library's default; mcmc: mgsr_solve's), the auto-stop
// window on, exposure compensation and the mutual stage as the fast preset runs them; density
// control's events resize the models, so they are scheduled after the end. Buffers that follow
// the model's screen footprint grow geometrically during the first iterations; from warm-up
// iteration 76 and mutual iteration 11 on, nothing may be allocated.
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
  if (const char* report = getenv("MGSR_ALLOC_REPORT")) {
    counter.report_stage = std::string(report) == "mutual" ? Stage::kMutual : Stage::kWarmup;
    counter.report_from = counter.report_stage == Stage::kWarmup ? 75 : 10;
  }
  solver.AddCallback(&counter);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  g_report = false;
  // counter.warmup[i] is iteration i + 2 (from one iteration's end to the next's).
  ASSERT_EQ(counter.warmup.size(), 149u);
  ASSERT_GE(counter.mutual.size(), 59u);
  int64_t late = 0;
  for (size_t i = 74; i < counter.warmup.size(); ++i) late += counter.warmup[i];
  for (size_t i = 9; i < counter.mutual.size(); ++i) late += counter.mutual[i];
  std::string per_iteration;
  for (int64_t a : counter.warmup) per_iteration += std::to_string(a) + " ";
  per_iteration += "| ";
  for (int64_t a : counter.mutual) per_iteration += std::to_string(a) + " ";
  EXPECT_EQ(late, 0) << "allocations per iteration (warm-up | mutual): " << per_iteration;
  // The count is real: the first iterations do allocate (they size every buffer).
  EXPECT_GT(counter.warmup[0] + counter.mutual[0], 0);
}

INSTANTIATE_TEST_SUITE_P(Density, IterationAllocationTest, ::testing::Values("reference", "mcmc"));

}  // namespace
}  // namespace mgsr
