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
#include <nlohmann/json.hpp>
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

// The classes a later audit added: camera fields of the json a reader must honour or refuse
// (sizes, focal lengths, lens distortion, camera models, duplicate frames), at the file's top
// level and per frame.
TEST_F(FuzzTest, JsonCameraFields) {
  const std::string scene = MakeScene(false, true);
  const std::string path = scene + "/transforms_train.json";
  std::string original;
  ASSERT_TRUE(ReadFileToString(path, &original).ok());
  const char* keys[] = {"w",  "h",  "fl_x", "fl_y", "cx", "cy",          "camera_angle_x",
                        "k1", "k2", "p1",   "p2",   "k4", "camera_model"};
  const nlohmann::json values[] = {1e12,    -5,   0.5,      0,         1e308,
                                   24,      12.5, "OPENCV", "PINHOLE", "OPENCV_FISHEYE",
                                   nullptr, "x",  0.1,      -0.2};
  Rng rng(5);
  int refused = 0;
  const int cases = 40;
  for (int c = 0; c < cases; ++c) {
    nlohmann::json j = nlohmann::json::parse(original);
    const std::string key = keys[rng.UniformInt(sizeof(keys) / sizeof(keys[0]))];
    const nlohmann::json& value = values[rng.UniformInt(sizeof(values) / sizeof(values[0]))];
    const int where = static_cast<int>(rng.UniformInt(3));  // file, a frame, a duplicated frame
    if (where == 0) {
      j[key] = value;
    } else {
      const size_t f = rng.UniformInt(j["frames"].size());
      j["frames"][f][key] = value;
      if (where == 2) j["frames"].push_back(j["frames"][f]);
    }
    ASSERT_TRUE(WriteStringToFileAtomic(path, j.dump()).ok());
    const auto r = testing::RunCommand("timeout 60 " + kTools + "/mgsr_solve --workspace " + scene +
                                       " --check");
    const std::string label = "case " + std::to_string(c) + ": " + key + " = " + value.dump() +
                              (where == 0   ? " (file)"
                               : where == 1 ? " (frame)"
                                            : " (duplicate)");
    ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 1) << label << "\n" << r.output;
    if (where == 2) {
      EXPECT_EQ(r.exit_code, 1) << label << ": a frame listed twice\n" << r.output;
    }
    if (r.exit_code == 0) continue;
    ++refused;
    int error_lines = 0;
    std::istringstream lines(r.output);
    for (std::string l; std::getline(lines, l);) error_lines += l.rfind("error: ", 0) == 0;
    EXPECT_EQ(error_lines, 1) << label << "\n" << r.output;
    EXPECT_NE(r.output.find(scene), std::string::npos) << label << ": names no file of the scene\n"
                                                       << r.output;
  }
  ASSERT_TRUE(WriteStringToFileAtomic(path, original).ok());
  EXPECT_GT(refused, cases / 4);
}

// Mesh files as mgsr_eval reads them: the face list's declared types and lengths, and values a
// float32 property cannot hold.
TEST_F(FuzzTest, PlyFaceTypesAndValues) {
  const std::string dir = testing::ScratchDir();
  const std::string good = dir + "/good.ply";
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty "
      "float z\nelement face 2\nproperty list ";
  const std::string vertices = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
  ASSERT_TRUE(WriteStringToFileAtomic(good, head + "uchar int vertex_indices\nend_header\n" +
                                                vertices + "3 0 1 2\n3 0 1 3\n")
                  .ok());
  const char* count_types[] = {"uchar", "int", "float", "uint"};
  const char* index_types[] = {"int", "uint", "short", "float", "double", "uchar"};
  const char* faces[] = {"3 0 1 2\n3 0 1 3\n", "2 0 1\n3 0 1 3\n",     "1 0\n3 0 1 3\n",
                         "3 0 1 2\n3 0 1 9\n", "3 0 1 2\n3 0.5 1 3\n", "3 0 1 2\n"};
  const char* coords[] = {"0 0 0\n", "1e39 0 0\n", "inf 0 0\n", "-1e38 0 0\n", "nan 0 0\n"};
  Rng rng(6);
  int refused = 0;
  const int cases = 30;
  for (int c = 0; c < cases; ++c) {
    const std::string ct = count_types[rng.UniformInt(4)], it = index_types[rng.UniformInt(6)];
    const std::string body = coords[rng.UniformInt(5)] + vertices.substr(6) +
                             faces[rng.UniformInt(sizeof(faces) / sizeof(faces[0]))];
    const std::string bad = dir + "/bad.ply";
    ASSERT_TRUE(
        WriteStringToFileAtomic(bad, head + ct + " " + it + " vertex_indices\nend_header\n" + body)
            .ok());
    const auto r =
        testing::RunCommand("timeout 60 " + kTools + "/mgsr_eval --mesh " + bad + " --gt " + good);
    const std::string label = "case " + std::to_string(c) + ": " + ct + "/" + it + "\n" + body;
    ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 1) << label << "\n" << r.output;
    if (r.exit_code == 0) continue;
    ++refused;
    EXPECT_EQ(r.output.rfind("error: ", 0), 0u) << label << r.output;
    EXPECT_NE(r.output.find("bad.ply"), std::string::npos) << label << r.output;
  }
  EXPECT_GT(refused, cases / 4);
}

// Flags with hostile values, with and without '=', and stray words: refused with one line (exit 2
// for the command line, 1 for a value out of range) or accepted; never a crash, a hang or a run
// that silently turned a flag on.
TEST_F(FuzzTest, FlagValuesAndStrayWords) {
  const std::string scene = MakeScene(false, false);
  const char* flags[] = {"--warmup_max_iterations",
                         "--mutual_iterations",
                         "--batch_views",
                         "--far_radius",
                         "--downscale",
                         "--lambda_normal",
                         "--overwrite",
                         "--resume",
                         "--test_every",
                         "--lambda_multiview_ncc",
                         "--multiview_neighbours"};
  const char* values[] = {"false", "-5", "inf", "1e12", "nan", "0", "-1", "2", "x", "true"};
  Rng rng(7);
  for (int c = 0; c < 40; ++c) {
    const std::string flag = flags[rng.UniformInt(sizeof(flags) / sizeof(flags[0]))];
    const std::string value = values[rng.UniformInt(sizeof(values) / sizeof(values[0]))];
    const bool equals = rng.UniformInt(2) == 0;
    const std::string args = flag + (equals ? "=" : " ") + value;
    const auto r = testing::RunCommand("timeout 60 " + kTools + "/mgsr_solve --workspace " + scene +
                                       " --check " + args);
    const std::string label = "case " + std::to_string(c) + ": " + args;
    ASSERT_TRUE(r.exit_code >= 0 && r.exit_code <= 2) << label << "\n" << r.output;
    if (r.exit_code != 0) {
      // Our one line ("error: ...") or gflags' for a value its type cannot parse ("ERROR: ...").
      EXPECT_TRUE(r.output.rfind("error: ", 0) == 0 || r.output.rfind("ERROR: ", 0) == 0)
          << label << "\n"
          << r.output;
    }
    // A boolean flag followed by a word: the word is never silently dropped (refused as a stray
    // word, or by gflags when it reads like a flag, "-5").
    if (!equals && (flag == "--overwrite" || flag == "--resume")) {
      EXPECT_NE(r.exit_code, 0) << label << "\n" << r.output;
    }
  }
}

// Two runs into one output folder at once: the second is refused with one line, the first ends
// as if alone.
TEST_F(FuzzTest, ConcurrentRunsIntoOneFolder) {
  const std::string scene = MakeScene(false, false);
  const std::string out = scene + "/../out";  // (ScratchDir again would empty the test's folder)
  const std::string run = kTools + "/mgsr_solve --workspace " + scene + " --output " + out +
                          " --overwrite --warmup_max_iterations 1500 --warmup_min_iterations 1000 "
                          "--mutual_iterations 600 --checkpoint_every 0";
  // The second starts once the first is training (its log exists).
  const auto r =
      testing::RunCommand("sh -c '(" + run + " > " + out + ".first 2>&1; echo $? > " + out +
                          ".rc) & while [ ! -e " + out + "/log.csv ]; do sleep 0.05; done; " + run +
                          " > " + out + ".second 2>&1; rc=$?; wait; exit $rc'");
  std::string second;
  ASSERT_TRUE(ReadFileToString(out + ".second", &second).ok());
  EXPECT_EQ(r.exit_code, 1) << second;
  EXPECT_NE(second.find("another run is writing into this output folder"), std::string::npos)
      << second;
  EXPECT_EQ(std::count(second.begin(), second.end(), '\n'), 1) << second;
  std::string rc, first;
  ASSERT_TRUE(ReadFileToString(out + ".rc", &rc).ok());
  ASSERT_TRUE(ReadFileToString(out + ".first", &first).ok());
  EXPECT_EQ(rc, "0\n") << first;
  EXPECT_TRUE(FileExists(out + "/metrics.json"));
}

}  // namespace
}  // namespace mgsr
