// The short 2DGS-only run the surface regression tests share: mgsr_synth writes a scene into
// `dir`/scene with the given flags, and mgsr_solve trains the 2DGS branch alone for 600 iterations
// (no auto-stop, no checkpoints) into `dir`/`out`, scoring itself against the scene's exact mesh;
// `solve_flags` are added to mgsr_solve's (the scene is written once per `dir`).
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "mgsr/io/file_util.h"
#include "test_util.h"

namespace mgsr::testing {

inline void ShortSurfelRun(const std::string& dir, const std::string& synth_flags,
                           CommandResult* solve, const std::string& solve_flags = "",
                           const std::string& out = "out") {
  const std::string tools = MGSR_TOOLS_DIR;
  if (!DirectoryExists(dir + "/scene")) {
    const CommandResult synth =
        RunCommand(tools + "/mgsr_synth --output " + dir + "/scene " + synth_flags);
    ASSERT_EQ(synth.exit_code, 0) << synth.output;
  }
  *solve =
      RunCommand(tools + "/mgsr_solve --workspace " + dir + "/scene --output " + dir + "/" + out +
                 " --method 2dgs --warmup_max_iterations 600 "
                 "--warmup_min_iterations 0 --mutual_iterations 0 --auto_stop=false "
                 "--eval_every 0 --checkpoint_every 0 " +
                 solve_flags);
  ASSERT_EQ(solve->exit_code, 0) << solve->output;
}

}  // namespace mgsr::testing
