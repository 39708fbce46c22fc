#include "mgsr/io/file_util.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

namespace mgsr {
namespace fs = std::filesystem;

Status ReadFileToString(const std::string& path, std::string* contents) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return Status::Error(path + ": is a folder, expected a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot open (missing or unreadable)");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return Status::Error(path + ": read error");
  *contents = ss.str();
  return Status::Ok();
}

Status WriteStringToFileAtomic(const std::string& path, const std::string& contents) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return Status::Error(path + ": cannot open for writing");
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.close();  // a full disk may only show when the last buffer goes out
    if (!out) {
      out.close();
      std::remove(tmp.c_str());
      return Status::Error(path + ": write failed (disk full?)");
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    return Status::Error(path + ": cannot move the finished file into place: " + ec.message());
  }
  return Status::Ok();
}

Status MakeDirectories(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec && !fs::is_directory(dir)) {
    return Status::Error(dir + ": cannot create folder: " + ec.message());
  }
  return Status::Ok();
}

bool FileExists(const std::string& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec);
}

bool DirectoryExists(const std::string& path) {
  std::error_code ec;
  return fs::is_directory(path, ec);
}

std::string FileStem(const std::string& path) { return fs::path(path).stem().string(); }

std::string JoinPath(const std::string& a, const std::string& b) {
  return (fs::path(a) / fs::path(b)).string();
}

}  // namespace mgsr
