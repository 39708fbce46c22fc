// Seeded fuzzing of every file mgsr_solve reads (#18). Each case mutates one file of a small scene
// (flipped, overwritten or zeroed bytes, extreme numbers in binary fields, a token of a text file
// replaced by nan, inf, -1, 1e308 or junk, lines dropped or doubled, truncation, trailing junk)
// and runs `mgsr_solve --check` on it under a time limit. Whatever the mutation, the program must
// exit 0 (the input is still usable) or 1 with exactly one error line naming a file or folder of
// the scene: never a crash, a hang, or an error that does not say where.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "mgsr/core/rng.h"
#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"
#include "test_util.h"

namespace mgsr {
namespace {

namespace fs = std::filesystem;

const std::string kTools = MGSR_TOOLS_DIR;

bool IsText(const std::string& path) {
  for (const char* ext : {".txt", ".json"}) {
    if (path.size() >= std::strlen(ext) &&
        path.compare(path.size() - std::strlen(ext), std::string::npos, ext) == 0)
      return true;
  }
  return false;
}

// One mutation of `data`; `what` says which, for the failure message.
std::string Mutate(const std::string& data, bool text, Rng* rng, std::string* what) {
  std::string out = data;
  const size_t n = std::max<size_t>(out.size(), 1);
  switch (rng->UniformInt(text ? 6 : 5)) {
    case 0: {  // a few random bytes
      const int count = 1 + static_cast<int>(rng->UniformInt(8));
      for (int i = 0; i < count && !out.empty(); ++i)
        out[rng->UniformInt(out.size())] = static_cast<char>(rng->UniformInt(256));
      *what = "flipped " + std::to_string(count) + " bytes";
      break;
    }
    case 1: {
      const size_t at = rng->UniformInt(n);
      out.resize(std::min(out.size(), at));
      *what = "truncated at " + std::to_string(at);
      break;
    }
    case 2: {
      const int count = 1 + static_cast<int>(rng->UniformInt(64));
      for (int i = 0; i < count; ++i) out.push_back(static_cast<char>(rng->UniformInt(256)));
      *what = "appended " + std::to_string(count) + " bytes";
      break;
    }
    case 3: {
      if (!text) {  // an extreme value in a 4- or 8-byte field
        const uint64_t values[] = {0xFFFFFFFFull,
                                   0x80000000ull,
                                   0x7FF0000000000000ull,
                                   0x7FF8000000000001ull,
                                   0,
                                   uint64_t{1} << 40,
                                   0xFFFFFFFFFFFFFFFFull,
                                   0x7F800000ull,
                                   0x4F000000ull};
        const uint64_t v = values[rng->UniformInt(sizeof(values) / sizeof(values[0]))];
        const size_t width = rng->UniformInt(2) == 0 ? 4 : 8;
        if (out.size() >= width) {
          const size_t at = rng->UniformInt(out.size() - width + 1) / width * width;
          std::memcpy(&out[at], &v, width);
          *what = "wrote " + std::to_string(v) + " over " + std::to_string(width) + " bytes at " +
                  std::to_string(at);
        }
      } else {  // a token replaced
        const char* tokens[] = {"nan", "inf", "-1",         "0", "1e308", "-1e308", "99999999999",
                                "abc", "",    "4294967344", "[", "{}",    "null",   "\"x\""};
        std::vector<std::pair<size_t, size_t>> spans;  // runs of non-space characters
        for (size_t i = 0; i < out.size();) {
          while (i < out.size() && std::isspace(static_cast<unsigned char>(out[i]))) ++i;
          const size_t start = i;
          while (i < out.size() && !std::isspace(static_cast<unsigned char>(out[i]))) ++i;
          if (i > start) spans.emplace_back(start, i - start);
        }
        if (!spans.empty()) {
          const auto [at, len] = spans[rng->UniformInt(spans.size())];
          const std::string token = tokens[rng->UniformInt(sizeof(tokens) / sizeof(tokens[0]))];
          *what = "replaced '" + out.substr(at, len) + "' by '" + token + "'";
          out.replace(at, len, token);
        }
      }
      break;
    }
    case 4: {
      if (!text) {  // a zeroed range
        const size_t at = rng->UniformInt(n), len = 1 + rng->UniformInt(64);
        for (size_t i = at; i < std::min(out.size(), at + len); ++i) out[i] = '\0';
        *what = "zeroed " + std::to_string(len) + " bytes at " + std::to_string(at);
      } else {  // a line dropped or doubled
        std::vector<std::string> lines;
        std::istringstream in(out);
        for (std::string l; std::getline(in, l);) lines.push_back(l);
        if (!lines.empty()) {
          const size_t k = rng->UniformInt(lines.size());
          const bool drop = rng->UniformInt(2) == 0;
          if (drop)
            lines.erase(lines.begin() + k);
          else
            lines.insert(lines.begin() + k, lines[k]);
          *what = (drop ? "dropped line " : "doubled line ") + std::to_string(k);
          out.clear();
          for (const std::string& l : lines) out += l + "\n";
        }
      }
      break;
    }
    default: {  // text: a digit changed
      std::vector<size_t> digits;
      for (size_t i = 0; i < out.size(); ++i) {
        if (std::isdigit(static_cast<unsigned char>(out[i]))) digits.push_back(i);
      }
      if (!digits.empty()) {
        const size_t at = digits[rng->UniformInt(digits.size())];
        out[at] = static_cast<char>('0' + rng->UniformInt(10));
        *what = "changed a digit at " + std::to_string(at);
      }
      break;
    }
  }
  if (what->empty()) *what = "unchanged";
  return out;
}

class FuzzTest : public ::testing::Test {
 protected:
  // A small scene; `text`: the COLMAP model as text files; `blender`: no COLMAP model at all.
  std::string MakeScene(bool text, bool blender) {
    const std::string dir = testing::ScratchDir() + "/scene";
    const auto r = testing::RunCommand(kTools + "/mgsr_synth --output " + dir +
                                       " --num_views 6 --width 24 --height 24 --num_points 60");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    if (text) {
      ColmapModel m;
      EXPECT_TRUE(ReadColmapModel(dir + "/sparse/0", &m).ok());
      for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
        fs::remove(dir + "/sparse/0/" + f);
      EXPECT_TRUE(WriteColmapModel(dir + "/sparse/0", m, ColmapFormat::kText).ok());
    }
    if (blender) fs::remove_all(dir + "/sparse");
    return dir;
  }

  // `cases` mutations spread over `files` (relative to the scene), each checked as above.
  void Fuzz(const std::string& scene, const std::vector<std::string>& files, int cases,
            uint64_t seed) {
    Rng rng(seed);
    int refused = 0, accepted = 0;
    for (int c = 0; c < cases; ++c) {
      const std::string file = files[rng.UniformInt(files.size())];
      const std::string path = scene + "/" + file;
      std::string original;
      ASSERT_TRUE(ReadFileToString(path, &original).ok()) << path;
      std::string what;
      const std::string mutated = Mutate(original, IsText(file), &rng, &what);
      ASSERT_TRUE(WriteStringToFileAtomic(path, mutated).ok());
      const auto r = testing::RunCommand("timeout 60 " + kTools + "/mgsr_solve --workspace " +
                                         scene + " --check");
      ASSERT_TRUE(WriteStringToFileAtomic(path, original).ok());
      const std::string label = "case " + std::to_string(c) + ": " + file + " " + what;
      ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 1)
          << label << ": exit " << r.exit_code << " (crash or hang)\n"
          << r.output;
      if (r.exit_code == 0) {
        ++accepted;
        continue;
      }
      ++refused;
      std::vector<std::string> errors;
      std::istringstream lines(r.output);
      for (std::string l; std::getline(lines, l);) {
        if (l.rfind("error: ", 0) == 0) errors.push_back(l);
      }
      ASSERT_EQ(errors.size(), 1u) << label << "\n" << r.output;
      EXPECT_NE(errors[0].find(scene), std::string::npos)
          << label << ": the error names no file of the scene\n"
          << r.output;
    }
    std::printf("%d cases: %d refused with one line naming the file, %d still usable\n", cases,
                refused, accepted);
    // Most mutations of a file the loader reads must be noticed; a fuzzer that never reached the
    // error paths would prove nothing.
    EXPECT_GT(refused, cases / 4) << refused << " refused, " << accepted << " accepted";
  }
};

TEST_F(FuzzTest, ColmapBinaryModel) {
  const std::string scene = MakeScene(false, false);
  Fuzz(scene, {"sparse/0/cameras.bin", "sparse/0/images.bin", "sparse/0/points3D.bin"}, 90, 1);
}

TEST_F(FuzzTest, ColmapTextModelAndSplit) {
  const std::string scene = MakeScene(true, false);
  Fuzz(scene, {"sparse/0/cameras.txt", "sparse/0/images.txt", "sparse/0/points3D.txt", "split.txt"},
       90, 2);
}

TEST_F(FuzzTest, ImagesAndMasks) {
  const std::string scene = MakeScene(false, false);
  Fuzz(scene, {"images/v000.png", "images/v003.png", "masks/v001.png", "masks/v004.png"}, 60, 3);
}

TEST_F(FuzzTest, BlenderJsonAndPointsPly) {
  const std::string scene = MakeScene(false, true);
  Fuzz(scene, {"transforms_train.json", "transforms_test.json", "points3d.ply"}, 90, 4);
}

}  // namespace
}  // namespace mgsr
