// The output folder of a run, kept honest: it never mixes one run's results with another's, and a
// folder that looks finished is finished.
//
// - A run starts in a missing or empty folder; a non-empty one is refused unless the run resumes
//   (its state, checkpoints/ and log.csv, is kept) or overwrites (the previous run's files are
//   removed). Either way the previous results are removed before anything new is written, so a
//   run that fails late cannot leave an old mesh beside new metrics.
// - Results are written through a temporary file and a rename and recorded with their size and
//   SHA-256; the manifest goes into metrics.json, written last.
// - A failed run calls Discard(): every result it wrote is removed again (its state stays, so
//   --resume can pick up from the last checkpoint).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mgsr/core/status.h"

namespace mgsr {

enum class OutputMode { kFresh, kResume, kOverwrite };

class OutputFolder {
 public:
  // Names (relative to the folder) of a run's results and of its resumable state; only these are
  // ever removed, whatever else the folder holds.
  static const std::vector<std::string>& ResultNames();
  static const std::vector<std::string>& StateNames();

  // Checks `dir` against `mode`; changes nothing on disk, so a run refused later (a bad scene, a
  // checkpoint that does not match) leaves the previous run as it was.
  static Status Open(const std::string& dir, OutputMode mode, OutputFolder* folder);
  // Before the run's first write: creates the folder and removes the previous run's results
  // (kOverwrite: its state too). Only the first call acts.
  Status Prepare();

  const std::string& dir() const { return dir_; }
  std::string Path(const std::string& relative) const;

  // Records a result already written under Path(relative) (by a PLY or image writer): reads it
  // back for its size and checksum.
  Status Record(const std::string& relative);
  // Writes a result atomically and records it.
  Status Write(const std::string& relative, const std::string& contents);

  // {"mesh.ply": {"bytes": N, "sha256": "..."}, ...} for metrics.json.
  nlohmann::json Manifest() const;
  // Removes every result this run wrote (and any partial temporaries).
  void Discard();

 private:
  struct Entry {
    std::string name, sha256;
    size_t bytes = 0;
  };
  Status ClearResults() const;

  std::string dir_;
  OutputMode mode_ = OutputMode::kFresh;
  bool prepared_ = false;
  std::vector<Entry> written_;
};

// Checks a finished run's folder against the manifest in its metrics.json: every listed file
// exists with its recorded size and checksum. The error names the first file that does not match.
Status VerifyOutputManifest(const std::string& dir, const nlohmann::json& metrics);

}  // namespace mgsr
