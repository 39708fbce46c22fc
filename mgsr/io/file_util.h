// Small file helpers shared by the readers and writers.
#pragma once

#include <string>

#include "mgsr/core/status.h"

namespace mgsr {

// Reads a whole file into `contents`; the error names the file.
Status ReadFileToString(const std::string& path, std::string* contents);

// Writes `contents` to `path` through a temporary file and a rename, so a crash or a full disk
// never leaves a half-written output under the final name.
Status WriteStringToFileAtomic(const std::string& path, const std::string& contents);

// Creates `dir` and its parents; fails with a message naming the folder.
Status MakeDirectories(const std::string& dir);

bool FileExists(const std::string& path);
bool DirectoryExists(const std::string& path);

// "a/b/c.png" -> "c", "c.png" -> "c".
std::string FileStem(const std::string& path);
std::string JoinPath(const std::string& a, const std::string& b);

}  // namespace mgsr
