#include "mgsr/core/profiler.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "solvers/profile_report.h"

namespace mgsr {
namespace {

// Busy-waits (a sleep may overshoot by far more on a loaded machine).
void SleepMs(int ms) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
  while (std::chrono::steady_clock::now() < until) {
  }
}

const ProfileEntry* Find(const std::vector<ProfileEntry>& entries, const std::string& context,
                         const std::string& name) {
  for (const ProfileEntry& e : entries) {
    if (e.context == context && e.name == name) return &e;
  }
  return nullptr;
}

struct ProfilerOn {
  ProfilerOn() {
    Profiler::SetEnabled(true);
    Profiler::Take();
  }
  ~ProfilerOn() { Profiler::SetEnabled(false); }
};

TEST(ProfilerTest, RecordsNothingWhenOff) {
  Profiler::SetEnabled(false);
  Profiler::Take();
  {
    ProfileContext c("3DGS");
    ProfileScope s("raster forward");
  }
  EXPECT_TRUE(Profiler::Take().empty());
}

TEST(ProfilerTest, ChargesNestedScopesExclusivelyPerContext) {
  ProfilerOn on;
  for (int i = 0; i < 2; ++i) {
    ProfileContext branch("2DGS");
    ProfileScope outer("losses");
    SleepMs(10);
    {
      ProfileScope inner("exposure");
      SleepMs(30);
    }
  }
  {
    ProfileScope solver("exposure fit");  // outside any context
    SleepMs(5);
  }
  const std::vector<ProfileEntry> e = Profiler::Take();
  ASSERT_EQ(e.size(), 3u);
  const ProfileEntry* losses = Find(e, "2DGS", "losses");
  const ProfileEntry* exposure = Find(e, "2DGS", "exposure");
  const ProfileEntry* fit = Find(e, "", "exposure fit");
  ASSERT_TRUE(losses && exposure && fit);
  EXPECT_EQ(losses->calls, 2);
  EXPECT_EQ(exposure->calls, 2);
  // Waits last at least as long as asked; the outer scope does not count the inner one's 60 ms
  // (counted inclusively it would hold 80 ms, more than the inner one).
  EXPECT_GE(losses->seconds, 0.020);
  EXPECT_GE(exposure->seconds, 0.060);
  EXPECT_LT(losses->seconds, exposure->seconds);
  EXPECT_GE(fit->seconds, 0.005);
  EXPECT_TRUE(Profiler::Take().empty());  // Take clears
}

TEST(ProfilerTest, IgnoresScopesOfOtherThreads) {
  ProfilerOn on;
  std::thread worker([] {
    ProfileScope s("raster forward");
    SleepMs(1);
  });
  worker.join();
  EXPECT_TRUE(Profiler::Take().empty());
}

TEST(ProfileReportTest, TableAndJsonPerIteration) {
  StageProfile p;
  p.stage = Stage::kWarmup;
  p.iterations = 10;
  p.seconds = 1.0;  // 100 ms per iteration
  p.entries = {{"2DGS", "raster forward", 0.2, 10},
               {"3DGS", "raster forward", 0.3, 10},
               {"3DGS", "loss: photo", 0.1, 10},
               {"", "exposure fit", 0.05, 1}};
  const std::string table = FormatProfile({p});
  EXPECT_NE(table.find("warm-up: 10 iterations, 100.00 ms per iteration"), std::string::npos)
      << table;
  // raster forward: 20 + 30 = 50 ms per iteration, half of it.
  EXPECT_NE(
      table.find("raster forward                 20.00     30.00         -     50.00   50.0%"),
      std::string::npos)
      << table;
  // Unscoped: 100 - 50 - 10 - 5 = 35 ms.
  EXPECT_NE(
      table.find("other (no scope)                                             35.00   35.0%"),
      std::string::npos)
      << table;
  EXPECT_NE(table.find("rasterizers (binning, forward, backward) 50.00 ms, the rest 50.00 ms"),
            std::string::npos)
      << table;
  // No callbacks scope: no line for the share without it.
  EXPECT_EQ(table.find("without the callbacks"), std::string::npos) << table;
  // With one (20 ms per iteration, taken from "other"): the rest stays 50 ms, 30 ms of it the
  // training's own, of an 80 ms training iteration.
  StageProfile with = p;
  with.entries.push_back({"", "callbacks", 0.2, 10});
  const std::string table2 = FormatProfile({with});
  EXPECT_NE(table2.find("the rest 50.00 ms"), std::string::npos) << table2;
  EXPECT_NE(table2.find("without the callbacks (20.00 ms: progress lines, diagnostics, "
                        "checkpoints) the rest 30.00 ms (37.5% of the training iteration)"),
            std::string::npos)
      << table2;
  const nlohmann::json j = ProfileToJson({p});
  EXPECT_EQ(j["warmup"]["iterations"], 10);
  EXPECT_NEAR(j["warmup"]["ms_per_iteration"].get<double>(), 100.0, 1e-9);
  EXPECT_NEAR(j["warmup"]["rasterizer_share"].get<double>(), 0.5, 1e-9);
  ASSERT_EQ(j["warmup"]["scopes"].size(), 4u);
  EXPECT_EQ(j["warmup"]["scopes"][3]["branch"], "solver");
  EXPECT_NEAR(j["warmup"]["scopes"][2]["ms_per_iteration"].get<double>(), 10.0, 1e-9);
}

}  // namespace
}  // namespace mgsr
