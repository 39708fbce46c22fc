#include "mgsr/io/output_folder.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "mgsr/core/sha256.h"
#include "mgsr/io/file_util.h"

namespace mgsr {
namespace fs = std::filesystem;
namespace {

// Removes `path` (a file or a folder of results) and a temporary left beside it.
Status RemovePath(const std::string& path) {
  std::error_code ec;
  fs::remove(path + ".tmp", ec);
  if (!fs::exists(fs::symlink_status(path, ec))) return Status::Ok();  // nothing (or no folder)
  fs::remove_all(path, ec);
  if (ec) return Status::Error(path + ": cannot remove the previous run's output: " + ec.message());
  return Status::Ok();
}

}  // namespace

const std::vector<std::string>& OutputFolder::ResultNames() {
  static const std::vector<std::string> names = {"metrics.json",       "mesh.ply",
                                                 "mesh.glb",           "point_cloud_2d.ply",
                                                 "point_cloud_3d.ply", "point_cloud_3d.splat",
                                                 "point_cloud_3d.spz", "renders"};
  return names;
}

const std::vector<std::string>& OutputFolder::StateNames() {
  static const std::vector<std::string> names = {"checkpoints", "log.csv", "colmap"};
  return names;
}

Status OutputFolder::Open(const std::string& dir, OutputMode mode, OutputFolder* folder) {
  // `folder` is set only once the lock is held: a refused open must leave nothing a Discard() of
  // the caller could clear (the folder may be another run's).
  *folder = OutputFolder();
  OutputFolder opened;
  opened.dir_ = dir;
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    return Status::Error(dir + ": output exists and is not a folder");
  if (mode == OutputMode::kFresh && fs::is_directory(dir, ec) &&
      fs::directory_iterator(dir, ec) != fs::directory_iterator()) {
    return Status::Error(dir +
                         ": output folder is not empty (use --overwrite to replace a previous "
                         "run, or --resume to continue it)");
  }
  opened.mode_ = mode;
  MGSR_RETURN_IF_ERROR(MakeDirectories(dir));
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0)
    return Status::Error(dir + ": cannot open the output folder: " + std::strerror(errno));
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    ::close(fd);
    if (err == EWOULDBLOCK)
      return Status::Error(dir +
                           ": another run is writing into this output folder; wait for it to end "
                           "or choose another --output");
    return Status::Error(dir + ": cannot lock the output folder: " + std::strerror(err));
  }
  opened.lock_ = std::shared_ptr<int>(new int(fd), [](int* p) {
    ::close(*p);
    delete p;
  });
  *folder = std::move(opened);
  return Status::Ok();
}

Status OutputFolder::Prepare() {
  if (prepared_) return Status::Ok();
  prepared_ = true;
  MGSR_RETURN_IF_ERROR(MakeDirectories(dir_));
  // A run set aside by an overwrite that never ended (killed) is not this run's to restore.
  MGSR_RETURN_IF_ERROR(RemovePath(Path(kPreviousRun)));
  if (mode_ != OutputMode::kOverwrite) return ClearResults();
  // Overwrite: the previous run's results and state move aside, metrics.json first (so no
  // manifest is ever left without its files).
  const std::string aside = Path(kPreviousRun);
  std::error_code ec;
  for (const std::vector<std::string>* names : {&ResultNames(), &StateNames()}) {
    for (const std::string& name : *names) {
      fs::remove(Path(name) + ".tmp", ec);
      if (!fs::exists(fs::symlink_status(Path(name), ec))) continue;
      MGSR_RETURN_IF_ERROR(MakeDirectories(aside));
      fs::rename(Path(name), JoinPath(aside, name), ec);
      if (ec)
        return Status::Error(Path(name) +
                             ": cannot set the previous run's output aside: " + ec.message());
    }
  }
  return Status::Ok();
}

void OutputFolder::Commit() {
  if (dir_.empty()) return;
  (void)RemovePath(Path(kPreviousRun));
}

Status OutputFolder::ClearResults() const {
  if (dir_.empty()) return Status::Ok();  // never opened: nothing of ours to clear
  // metrics.json goes first (it leads ResultNames), so an interrupted clean-up never leaves a
  // manifest without its files.
  for (const std::string& name : ResultNames()) MGSR_RETURN_IF_ERROR(RemovePath(Path(name)));
  return Status::Ok();
}

std::string OutputFolder::Path(const std::string& relative) const {
  return JoinPath(dir_, relative);
}

Status OutputFolder::Record(const std::string& relative) {
  std::string bytes;
  MGSR_RETURN_IF_ERROR(ReadFileToString(Path(relative), &bytes));
  for (Entry& e : written_) {
    if (e.name == relative) {
      e.bytes = bytes.size();
      e.sha256 = Sha256Hex(bytes);
      return Status::Ok();
    }
  }
  written_.push_back({relative, Sha256Hex(bytes), bytes.size()});
  return Status::Ok();
}

Status OutputFolder::Write(const std::string& relative, const std::string& contents) {
  MGSR_RETURN_IF_ERROR(WriteStringToFileAtomic(Path(relative), contents));
  return Record(relative);
}

nlohmann::json OutputFolder::Manifest() const {
  nlohmann::json files = nlohmann::json::object();
  for (const Entry& e : written_) files[e.name] = {{"bytes", e.bytes}, {"sha256", e.sha256}};
  return files;
}

void OutputFolder::Discard() {
  if (dir_.empty()) return;
  // Best effort: the run is failing already, and its own error is the one to report. Everything
  // a run records lies under ResultNames(), so clearing those takes back what it wrote.
  written_.clear();
  (void)ClearResults();
  // Put back what an overwrite set aside, where this run left nothing of the same name (a run
  // stopped while writing keeps its own checkpoint for --resume).
  const std::string aside = Path(kPreviousRun);
  std::error_code ec;
  if (!fs::is_directory(aside, ec)) return;
  // State first, results in reverse (metrics.json last: never a manifest without its files).
  std::vector<std::string> names = StateNames();
  names.insert(names.end(), ResultNames().rbegin(), ResultNames().rend());
  {
    for (const std::string& name : names) {
      const std::string from = JoinPath(aside, name);
      if (!fs::exists(fs::symlink_status(from, ec)) ||
          fs::exists(fs::symlink_status(Path(name), ec)))
        continue;
      fs::rename(from, Path(name), ec);
    }
  }
  fs::remove_all(aside, ec);
}

Status VerifyOutputManifest(const std::string& dir, const nlohmann::json& metrics) {
  const std::string where = JoinPath(dir, "metrics.json");
  if (!metrics.contains("files") || !metrics["files"].is_object())
    return Status::Error(where + ": no list of output files (written before checksums were kept?)");
  for (const auto& [name, entry] : metrics["files"].items()) {
    const std::string path = JoinPath(dir, name);
    std::string bytes;
    if (!ReadFileToString(path, &bytes).ok())
      return Status::Error(path + ": listed in " + where + " but missing");
    if (!entry.is_object() || !entry.contains("sha256") || !entry["sha256"].is_string() ||
        entry["sha256"].get<std::string>() != Sha256Hex(bytes)) {
      return Status::Error(path + ": does not match the checksum in " + where +
                           " (written by another run, or changed since)");
    }
  }
  return Status::Ok();
}

}  // namespace mgsr
