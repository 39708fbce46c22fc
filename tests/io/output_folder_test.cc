#include "mgsr/io/output_folder.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "mgsr/core/sha256.h"
#include "mgsr/io/file_util.h"
#include "test_util.h"

namespace mgsr {
namespace {
namespace fs = std::filesystem;

// A folder as a finished run leaves it, plus a file that is not ours.
std::string PreviousRun() {
  const std::string dir = testing::ScratchDir() + "/run";
  EXPECT_TRUE(MakeDirectories(dir + "/renders").ok());
  EXPECT_TRUE(MakeDirectories(dir + "/checkpoints").ok());
  for (const char* f : {"metrics.json", "mesh.ply", "point_cloud_2d.ply", "renders/v_gt.png",
                        "checkpoints/latest.ckpt", "log.csv", "notes.txt"}) {
    EXPECT_TRUE(WriteStringToFileAtomic(dir + "/" + f, "old").ok());
  }
  return dir;
}

TEST(OutputFolderTest, ANonEmptyFolderIsRefusedUnlessResumingOrOverwriting) {
  const std::string dir = PreviousRun();
  OutputFolder out;
  const Status s = OutputFolder::Open(dir, OutputMode::kFresh, &out);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), dir +
                             ": output folder is not empty (use --overwrite to replace a "
                             "previous run, or --resume to continue it)");
  EXPECT_TRUE(FileExists(dir + "/mesh.ply"));  // nothing touched
  // A missing or empty folder is fine (created, empty, to be locked); a file where the folder
  // should be is not.
  ASSERT_TRUE(OutputFolder::Open(dir + "/new/deeper", OutputMode::kFresh, &out).ok());
  EXPECT_TRUE(fs::is_empty(dir + "/new/deeper"));
  ASSERT_TRUE(out.Prepare().ok());
  EXPECT_TRUE(DirectoryExists(dir + "/new/deeper"));
  ASSERT_TRUE(OutputFolder::Open(dir + "/new/deeper", OutputMode::kFresh, &out).ok());
  EXPECT_FALSE(OutputFolder::Open(dir + "/notes.txt", OutputMode::kOverwrite, &out).ok());
}

TEST(OutputFolderTest, OverwriteClearsTheRunAndResumeKeepsItsState) {
  std::string dir = PreviousRun();
  OutputFolder out;
  ASSERT_TRUE(OutputFolder::Open(dir, OutputMode::kOverwrite, &out).ok());
  EXPECT_TRUE(FileExists(dir + "/mesh.ply"));  // nothing goes before the run's first write
  ASSERT_TRUE(out.Prepare().ok());
  const char* const run_files[] = {"metrics.json", "mesh.ply",    "point_cloud_2d.ply",
                                   "renders",      "checkpoints", "log.csv"};
  for (const char* f : run_files) EXPECT_FALSE(fs::exists(dir + "/" + f)) << f;
  EXPECT_TRUE(FileExists(dir + "/notes.txt"));  // not ours: left alone
  // The overwriting run fails: the previous run comes back as it was, except what the failing
  // run left of its own (its checkpoint, for --resume).
  ASSERT_TRUE(WriteStringToFileAtomic(out.Path("mesh.ply"), "new").ok());
  ASSERT_TRUE(out.Record("mesh.ply").ok());
  ASSERT_TRUE(WriteStringToFileAtomic(out.Path("log.csv"), "new").ok());
  out.Discard();
  std::string text;
  for (const char* f : {"metrics.json", "mesh.ply", "point_cloud_2d.ply", "renders/v_gt.png",
                        "checkpoints/latest.ckpt"}) {
    ASSERT_TRUE(ReadFileToString(dir + "/" + f, &text).ok()) << f;
    EXPECT_EQ(text, "old") << f;
  }
  ASSERT_TRUE(ReadFileToString(dir + "/log.csv", &text).ok());
  EXPECT_EQ(text, "new");
  EXPECT_FALSE(fs::exists(dir + "/" + OutputFolder::kPreviousRun));
  // It finishes: the previous run is gone for good.
  ASSERT_TRUE(OutputFolder::Open(dir, OutputMode::kOverwrite, &out).ok());
  ASSERT_TRUE(out.Prepare().ok());
  EXPECT_TRUE(fs::exists(dir + "/" + OutputFolder::kPreviousRun));
  out.Commit();
  EXPECT_FALSE(fs::exists(dir + "/" + OutputFolder::kPreviousRun));
  for (const char* f : run_files) EXPECT_FALSE(fs::exists(dir + "/" + f)) << f;

  dir = PreviousRun();
  ASSERT_TRUE(OutputFolder::Open(dir, OutputMode::kResume, &out).ok());
  EXPECT_TRUE(FileExists(dir + "/mesh.ply"));
  ASSERT_TRUE(out.Prepare().ok());
  for (const char* f : {"metrics.json", "mesh.ply", "point_cloud_2d.ply", "renders"})
    EXPECT_FALSE(fs::exists(dir + "/" + f)) << f;
  for (const char* f : {"checkpoints/latest.ckpt", "log.csv", "notes.txt"})
    EXPECT_TRUE(FileExists(dir + "/" + f)) << f;
}

TEST(OutputFolderTest, OneRunAtATime) {
  const std::string dir = testing::ScratchDir() + "/run";
  OutputFolder first, second;
  ASSERT_TRUE(OutputFolder::Open(dir, OutputMode::kFresh, &first).ok());
  const Status s = OutputFolder::Open(dir, OutputMode::kOverwrite, &second);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), dir +
                             ": another run is writing into this output folder; wait for it to "
                             "end or choose another --output");
  // The refused run cleans up after its own failure: that must not touch the first run's results.
  ASSERT_TRUE(first.Prepare().ok());
  ASSERT_TRUE(WriteStringToFileAtomic(first.Path("mesh.ply"), "first").ok());
  ASSERT_TRUE(first.Record("mesh.ply").ok());
  second.Discard();
  EXPECT_TRUE(FileExists(dir + "/mesh.ply"));
  EXPECT_TRUE(second.dir().empty());
  first = OutputFolder();  // the first run ends: its lock goes with it
  EXPECT_TRUE(OutputFolder::Open(dir, OutputMode::kOverwrite, &second).ok());
}

TEST(OutputFolderTest, TheManifestVouchesForEachFileAndDiscardTakesThemBack) {
  const std::string dir = testing::ScratchDir() + "/run";
  OutputFolder out;
  ASSERT_TRUE(OutputFolder::Open(dir, OutputMode::kFresh, &out).ok());
  ASSERT_TRUE(out.Prepare().ok());
  ASSERT_TRUE(out.Write("mesh.ply", "mesh bytes").ok());
  ASSERT_TRUE(MakeDirectories(out.Path("renders")).ok());
  ASSERT_TRUE(WriteStringToFileAtomic(out.Path("renders/a.png"), "png").ok());
  ASSERT_TRUE(out.Record("renders/a.png").ok());
  EXPECT_FALSE(out.Record("renders/missing.png").ok());
  nlohmann::json metrics;
  metrics["files"] = out.Manifest();
  ASSERT_EQ(metrics["files"].size(), 2u);
  EXPECT_EQ(metrics["files"]["mesh.ply"]["bytes"], 10);
  EXPECT_EQ(metrics["files"]["mesh.ply"]["sha256"], Sha256Hex("mesh bytes"));
  EXPECT_TRUE(VerifyOutputManifest(dir, metrics).ok());

  // Another run's mesh in its place, a missing render, no manifest at all: each is named.
  ASSERT_TRUE(WriteStringToFileAtomic(out.Path("mesh.ply"), "other mesh").ok());
  Status s = VerifyOutputManifest(dir, metrics);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message().rfind(dir + "/mesh.ply: does not match the checksum", 0), 0u)
      << s.message();
  ASSERT_TRUE(out.Write("mesh.ply", "mesh bytes").ok());
  fs::remove(out.Path("renders/a.png"));
  s = VerifyOutputManifest(dir, metrics);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("renders/a.png: listed in"), std::string::npos) << s.message();
  EXPECT_FALSE(VerifyOutputManifest(dir, nlohmann::json::object()).ok());

  ASSERT_TRUE(out.Write("metrics.json", "{}").ok());
  out.Discard();
  for (const char* f : {"metrics.json", "mesh.ply", "renders"})
    EXPECT_FALSE(fs::exists(dir + "/" + f)) << f;
  EXPECT_TRUE(DirectoryExists(dir));
}

}  // namespace
}  // namespace mgsr
