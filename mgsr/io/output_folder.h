// The output folder of a run, kept honest: it never mixes one run's results with another's, and a
// folder that looks finished is finished.
//
// - One run at a time: the folder is locked (flock on the folder itself) from Open to the end of
//   the process; a second run into it is refused at once.
// - A run starts in a missing or empty folder; a non-empty one is refused unless the run resumes
//   (its state, checkpoints/ and log.csv, is kept) or overwrites. Either way the previous results
//   leave before anything new is written, so a run that fails late cannot leave an old mesh beside
//   new metrics. Overwriting sets the previous run aside (.mgsr-previous/) rather than deleting
//   it: a run that then fails puts it back, a finished one (Commit) deletes it.
// - Results are written through a temporary file and a rename and recorded with their size and
//   SHA-256; the manifest goes into metrics.json, written last.
// - A failed run calls Discard(): every result it wrote is removed again (its state stays, so
//   --resume can pick up from the last checkpoint).
#pragma once

#include <memory>
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

  // Checks `dir` against `mode` and locks it (creating it when missing); changes nothing else on
  // disk, so a run refused later (a bad scene, a checkpoint that does not match) leaves the
  // previous run as it was.
  static Status Open(const std::string& dir, OutputMode mode, OutputFolder* folder);
  // Before the run's first write: removes the previous run's results (kOverwrite: sets its results
  // and state aside instead). Only the first call acts.
  Status Prepare();
  // The run finished: the previous run set aside by an overwrite is deleted.
  void Commit();

  const std::string& dir() const { return dir_; }
  std::string Path(const std::string& relative) const;

  // Records a result already written under Path(relative) (by a PLY or image writer): reads it
  // back for its size and checksum.
  Status Record(const std::string& relative);
  // Writes a result atomically and records it.
  Status Write(const std::string& relative, const std::string& contents);

  // {"mesh.ply": {"bytes": N, "sha256": "..."}, ...} for metrics.json.
  nlohmann::json Manifest() const;
  // Removes every result this run wrote (and any partial temporaries), and puts back what an
  // overwrite set aside (where this run left nothing of the same name).
  void Discard();
  // The folder a previous run is set aside in while an overwriting run is under way.
  static constexpr const char* kPreviousRun = ".mgsr-previous";

 private:
  struct Entry {
    std::string name, sha256;
    size_t bytes = 0;
  };
  Status ClearResults() const;

  std::string dir_;
  std::shared_ptr<int> lock_;  // the locked folder's descriptor, closed with the last copy
  OutputMode mode_ = OutputMode::kFresh;
  bool prepared_ = false;
  std::vector<Entry> written_;
};

// Checks a finished run's folder against the manifest in its metrics.json: every listed file
// exists with its recorded size and checksum. The error names the first file that does not match.
Status VerifyOutputManifest(const std::string& dir, const nlohmann::json& metrics);

}  // namespace mgsr
