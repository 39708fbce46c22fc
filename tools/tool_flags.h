// Command-line parsing shared by the tools: gflags, with a --help that shows the tool's own flags
// only (not the ~60 of glog and gflags), grouped by topic, each with its type and default.
// --helpfull still lists every flag.
#pragma once

#include <gflags/gflags.h>

#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

namespace mgsr_tools {

struct FlagTopic {
  const char* title;
  std::vector<const char*> flags;
};

namespace internal {

// Flags defined in this directory (a tool's .cc or a shared tools/*_flags.h).
inline bool IsToolFlag(const gflags::CommandLineFlagInfo& f) {
  return f.filename.find("tools/mgsr_") != std::string::npos ||
         f.filename.find("tools/colmap_flags.h") != std::string::npos;
}

// The description, wrapped to `width` columns after an indent.
inline void PrintWrapped(const std::string& text, size_t indent, size_t width) {
  std::string line;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find(' ', pos);
    if (end == std::string::npos) end = text.size();
    const std::string word = text.substr(pos, end - pos);
    if (!line.empty() && indent + line.size() + 1 + word.size() > width) {
      std::printf("%*s%s\n", static_cast<int>(indent), "", line.c_str());
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
    pos = end + 1;
  }
  if (!line.empty()) std::printf("%*s%s\n", static_cast<int>(indent), "", line.c_str());
}

inline void PrintFlag(const gflags::CommandLineFlagInfo& f) {
  const std::string value = f.type == "string" ? "\"" + f.default_value + "\"" : f.default_value;
  std::printf("  --%s (%s, default %s)\n", f.name.c_str(), f.type.c_str(), value.c_str());
  PrintWrapped(f.description, 6, 100);
}

}  // namespace internal

// Parses the command line (removing the flags from argv). With --help: prints `usage`, then this
// tool's flags under `topics` in their order, any not listed under "Other", and exits with 0.
inline void ParseToolFlags(const std::string& usage, const std::vector<FlagTopic>& topics,
                           int* argc, char*** argv) {
  gflags::SetUsageMessage(usage);
  gflags::ParseCommandLineNonHelpFlags(argc, argv, true);
  std::string help;
  if (gflags::GetCommandLineOption("help", &help) && help == "true") {
    std::vector<gflags::CommandLineFlagInfo> all;
    gflags::GetAllFlags(&all);
    std::map<std::string, gflags::CommandLineFlagInfo> own;
    for (const auto& f : all) {
      if (internal::IsToolFlag(f)) own[f.name] = f;
    }
    std::printf("usage: %s\n", usage.c_str());
    for (const FlagTopic& topic : topics) {
      bool title = false;
      for (const char* name : topic.flags) {
        const auto it = own.find(name);
        if (it == own.end()) continue;
        if (!title) std::printf("\n%s:\n", topic.title);
        title = true;
        internal::PrintFlag(it->second);
        own.erase(it);
      }
    }
    if (!own.empty()) {
      std::printf("\nOther:\n");
      for (const auto& [name, f] : own) internal::PrintFlag(f);
    }
    std::printf("\n--helpfull lists every flag, also those of glog and gflags.\n");
    std::exit(0);
  }
  gflags::HandleCommandLineHelpFlags();  // --helpfull, --version, ...
  // gflags takes a bare boolean flag as true and leaves a following word ("--overwrite false") as
  // a positional argument; no tool takes one, so a stray word is a mistake that would otherwise
  // silently turn a flag on.
  if (*argc > 1) {
    std::fprintf(stderr,
                 "error: unexpected argument '%s' (no tool takes positional arguments; give a "
                 "flag its value with '=', e.g. --overwrite=false)\n",
                 (*argv)[1]);
    std::exit(2);
  }
}

}  // namespace mgsr_tools
