// mgsr_solve under mpirun (built with -DMGSR_WITH_MPI=ON only): processes that share each batch
// train the models one process trains with the same batch, byte for byte; a run checkpointed by
// one process continues under two; bad set-ups end the whole job with one clear message.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "mgsr/io/file_util.h"
#include "test_util.h"

namespace mgsr {
namespace {

namespace fs = std::filesystem;

const std::string kTools = MGSR_TOOLS_DIR;
// Open MPI refuses root (CI runs as root) unless told; each process runs one OpenMP thread (2
// processes x 1 thread on the 2-core machine) and yields while it waits for the other (ctest runs
// another test beside this one: busy-polling processes would share 2 cores with it).
const std::string kMpirun =
    "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_mpi_yield_when_idle=1 "
    "OMP_NUM_THREADS=1 mpirun --oversubscribe ";

class MpiTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = (fs::path(::testing::TempDir()) / "mgsr_tests" / ("mpi_" + std::to_string(getpid())))
                 .string();
    fs::remove_all(scene_);
    const auto r = testing::RunCommand(kTools + "/mgsr_synth --output " + scene_ +
                                       " --width 48 --height 48 --num_views 16 --seed 5");
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static std::string Solve(const std::string& out, const std::string& extra) {
    return kTools + "/mgsr_solve --workspace " + scene_ + " --output " + out +
           " --warmup_min_iterations 0 --warmup_max_iterations 160 --mutual_iterations 60 "
           "--log_every 20 --eval_every 0 " +
           extra;
  }
  static void ExpectSameOutputs(const std::string& a, const std::string& b) {
    for (const char* f : {"point_cloud_2d.ply", "point_cloud_3d.ply", "mesh.ply"}) {
      std::string x, y;
      ASSERT_TRUE(ReadFileToString(a + "/" + f, &x).ok()) << a << "/" << f;
      ASSERT_TRUE(ReadFileToString(b + "/" + f, &y).ok()) << b << "/" << f;
      EXPECT_TRUE(x == y) << f << " differs between " << a << " and " << b;
    }
  }
  static std::string scene_;
};
std::string MpiTest::scene_;

TEST_F(MpiTest, TwoProcessesTrainTheModelsOfOneWithTheSameBatch) {
  const std::string dir = scene_ + "_same";
  fs::remove_all(dir);
  auto one = testing::RunCommand(Solve(dir + "/one", "--batch_views 2"));
  ASSERT_EQ(one.exit_code, 0) << one.output;
  auto two = testing::RunCommand(kMpirun + "-np 2 " + Solve(dir + "/two", "--batch_views 2"));
  ASSERT_EQ(two.exit_code, 0) << two.output;
  EXPECT_NE(two.output.find("batches: 2 views per step"), std::string::npos) << two.output;
  EXPECT_NE(two.output.find("2 processes"), std::string::npos) << two.output;
  // Process 0 alone prints (one summary line, not two).
  EXPECT_EQ(two.output.find("mesh: "), two.output.rfind("mesh: ")) << two.output;
  ExpectSameOutputs(dir + "/one", dir + "/two");
  // A batch of 4 over 2 processes (2 views each): the same again.
  one = testing::RunCommand(Solve(dir + "/one4", "--batch_views 4"));
  ASSERT_EQ(one.exit_code, 0) << one.output;
  two = testing::RunCommand(kMpirun + "-np 2 " + Solve(dir + "/two4", "--batch_views 4"));
  ASSERT_EQ(two.exit_code, 0) << two.output;
  ExpectSameOutputs(dir + "/one4", dir + "/two4");
}

TEST_F(MpiTest, ARunInterruptedInOneProcessContinuesInTwo) {
  const std::string dir = scene_ + "_resume";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string flags = "--batch_views 2 --checkpoint_every 10 --warmup_max_iterations 600";
  auto whole = testing::RunCommand(Solve(dir + "/whole", flags));
  ASSERT_EQ(whole.exit_code, 0) << whole.output;
  // Ctrl-C once the first checkpoint exists: the state is saved at an iteration boundary.
  const std::string out = dir + "/split";
  const std::string script = Solve(out, flags) + " > " + out +
                             ".log 2>&1 & pid=\\$!; "
                             "until [ -f " +
                             out +
                             "/checkpoints/latest.ckpt ] || ! kill -0 \\$pid 2>/dev/null; "
                             "do sleep 0.01; done; kill -INT \\$pid 2>/dev/null; wait \\$pid; "
                             "echo exit=\\$?";
  const auto stopped = testing::RunCommand("bash -c \"" + script + "\"");
  ASSERT_NE(stopped.output.find("exit=130"), std::string::npos)
      << "the run ended before the signal: " << stopped.output;
  const auto resumed = testing::RunCommand(kMpirun + "-np 2 " + Solve(out, flags + " --resume"));
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("resuming from"), std::string::npos) << resumed.output;
  ExpectSameOutputs(dir + "/whole", out);
}

TEST_F(MpiTest, AProcessThatDiesEndsTheJobAndLeavesTheCheckpoint) {
  const std::string dir = scene_ + "_dies";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string out = dir + "/run";
  const std::string flags = "--batch_views 2 --checkpoint_every 5 --warmup_max_iterations 4000";
  // Once a checkpoint exists, one of the job's two processes is killed outright.
  const std::string script =
      kMpirun + "-np 2 " + Solve(out, flags) + " > " + out +
      ".log 2>&1 & job=\\$!; "
      "until [ -f " +
      out +
      "/checkpoints/latest.ckpt ] || ! kill -0 \\$job 2>/dev/null; do sleep 0.01; done; "
      "pkill -KILL -n -f 'mgsr_solve --workspace .* --output " +
      out + " '; wait \\$job; echo exit=\\$?";
  const auto r = testing::RunCommand("bash -c \"" + script + "\"");
  EXPECT_EQ(r.output.find("exit=0"), std::string::npos) << "the job did not end: " << r.output;
  EXPECT_FALSE(fs::exists(out + "/metrics.json"));
  // The last checkpoint is whole: a new run accepts it.
  const auto check = testing::RunCommand(Solve(out, flags + " --resume --check"));
  EXPECT_EQ(check.exit_code, 0) << check.output;
  EXPECT_NE(check.output.find("check: the scene and the checkpoint can be trained"),
            std::string::npos)
      << check.output;
}

TEST_F(MpiTest, BadSetupsEndTheJobWithOneMessage) {
  const std::string dir = scene_ + "_bad";
  fs::remove_all(dir);
  // A batch the processes cannot share evenly.
  auto r = testing::RunCommand(kMpirun + "-np 2 " + Solve(dir + "/odd", "--batch_views 3"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("error: --batch_views 3 is not divisible by the 2 MPI ranks"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir + "/odd/metrics.json"));
  // Processes started with other options (another seed): refused before any training.
  r = testing::RunCommand(kMpirun + "-np 1 " + Solve(dir + "/mixed", "--batch_views 2") +
                          " : -np 1 " + Solve(dir + "/mixed", "--batch_views 2 --seed 7"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("MPI process 1 has other options than process 0"), std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(dir + "/mixed/metrics.json"));
}

}  // namespace
}  // namespace mgsr
