// Helpers shared by the tests: scratch folders, a small synthetic scene, running the CLIs.
#pragma once

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include "mgsr/io/scene.h"
#include "mgsr/synth/synthetic_scene.h"

namespace mgsr::testing {

// A fresh empty folder under the test temp dir, unique per test.
inline std::string ScratchDir(const std::string& tag = "") {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string(info->test_suite_name()) + "_" + info->name() + tag;
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / "mgsr_tests" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

// A small, fast synthetic scene (12 views of 32x32) written into `dir`.
inline SynthOptions SmallSynthOptions() {
  SynthOptions o;
  o.shape = "sphere";
  o.detail = 0;
  o.num_views = 12;
  o.width = 32;
  o.height = 32;
  o.test_every = 4;
  o.num_points = 200;
  o.supersampling = 1;
  return o;
}

// A 48 px, 16-view scene under constant light (so test views are predictable), written to `dir`
// and loaded: what the solver tests train on.
inline Scene TinySolverScene(const std::string& dir) {
  SynthOptions so = SmallSynthOptions();
  so.width = so.height = 48;
  so.varying_light = false;
  so.num_views = 16;
  EXPECT_TRUE(WriteSyntheticScene(so, dir).ok());
  Scene scene;
  EXPECT_TRUE(LoadScene(dir, SceneOptions(), &scene).ok());
  return scene;
}

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

inline CommandResult RunCommand(const std::string& command) {
  CommandResult r;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return r;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) r.output.append(buffer, n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

inline std::string SharedDataDir() { return MGSR_SHARED_DATA_DIR; }
inline bool HaveSharedData() {
  return std::filesystem::exists(std::filesystem::path(SharedDataDir()) / "suzanne" / "sparse");
}

}  // namespace mgsr::testing
