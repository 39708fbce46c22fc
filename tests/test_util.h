// Helpers shared by the tests: scratch folders, a small synthetic scene, running the CLIs.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/scene.h"
#include "mgsr/synth/synthetic_scene.h"

namespace mgsr::testing {

// A fresh empty folder under the test temp dir, unique per test.
inline std::string ScratchDir(const std::string& tag = "") {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string(info->test_suite_name()) + "_" + info->name() + tag;
  for (char& c : name) {
    if (c == '/') c = '_';
  }
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / "mgsr_tests" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

// A small, fast synthetic scene (12 views of 32x32) written into `dir`.
inline SynthOptions SmallSynthOptions() {
  SynthOptions o;
  o.shape = "sphere";
  o.detail = 0;
  o.num_views = 12;
  o.width = 32;
  o.height = 32;
  o.test_every = 4;
  o.num_points = 200;
  o.supersampling = 1;
  return o;
}

// A 48 px, 16-view scene under constant light (so test views are predictable), written to `dir`
// and loaded: what the solver tests train on.
inline Scene TinySolverScene(const std::string& dir) {
  SynthOptions so = SmallSynthOptions();
  so.width = so.height = 48;
  so.varying_light = false;
  so.num_views = 16;
  EXPECT_TRUE(WriteSyntheticScene(so, dir).ok());
  Scene scene;
  EXPECT_TRUE(LoadScene(dir, SceneOptions(), &scene).ok());
  return scene;
}

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

inline CommandResult RunCommand(const std::string& command) {
  CommandResult r;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return r;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) r.output.append(buffer, n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// The SSIM map of plane b against plane a (w x h, row-major), summed: a direct, non-separable
// 11x11 Gaussian window (sigma 1.5) with zero padding, C1 = 0.01^2, C2 = 0.03^2, in double
// precision. An independent reference for the separable and fused implementations.
inline double DirectSsimSum(const double* a, const double* b, int w, int h) {
  const double C1 = 1e-4, C2 = 9e-4, sigma = 1.5;
  double g[11][11], norm = 0;
  for (int i = 0; i < 11; ++i) {
    for (int j = 0; j < 11; ++j)
      norm += g[i][j] = std::exp(-((i - 5) * (i - 5) + (j - 5) * (j - 5)) / (2 * sigma * sigma));
  }
  double total = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double ma = 0, mb = 0, saa = 0, sbb = 0, sab = 0;
      for (int i = 0; i < 11; ++i) {
        for (int j = 0; j < 11; ++j) {
          const int yy = y + i - 5, xx = x + j - 5;
          if (yy < 0 || xx < 0 || yy >= h || xx >= w) continue;  // zero padding
          const double wt = g[i][j] / norm, va = a[yy * w + xx], vb = b[yy * w + xx];
          ma += wt * va;
          mb += wt * vb;
          saa += wt * va * va;
          sbb += wt * vb * vb;
          sab += wt * va * vb;
        }
      }
      total += ((2 * ma * mb + C1) * (2 * (sab - ma * mb) + C2)) /
               ((ma * ma + mb * mb + C1) * (saa - ma * ma + sbb - mb * mb + C2));
    }
  }
  return total;
}

inline std::string SharedDataDir() { return MGSR_SHARED_DATA_DIR; }
inline bool HaveSharedData() {
  return std::filesystem::exists(std::filesystem::path(SharedDataDir()) / "suzanne" / "sparse");
}

// d loss / d *value by central differences (the value is restored).
template <typename Loss>
double CentralDifference(const Loss& loss, double* value, double h = 1e-6) {
  const double keep = *value;
  *value = keep + h;
  const double plus = loss();
  *value = keep - h;
  const double minus = loss();
  *value = keep;
  return (plus - minus) / (2 * h);
}

// A JPEG of `image` with an EXIF APP1 segment whose IFD0 holds Orientation = `orientation`
// (little-endian TIFF), as cameras write it, at dir/o<orientation>.jpg.
inline std::string WriteJpegWithOrientation(const std::string& dir, const Image& image,
                                            int orientation) {
  const std::string plain = dir + "/plain.jpg";
  EXPECT_TRUE(WriteImage(plain, image).ok());
  std::string jpeg;
  EXPECT_TRUE(ReadFileToString(plain, &jpeg).ok());
  std::string tiff = std::string("II*\0", 4) + std::string("\x08\0\0\0", 4);  // IFD0 at 8
  tiff += std::string("\x01\0", 2);                                           // one entry
  tiff += std::string("\x12\x01\x03\0\x01\0\0\0", 8);  // tag 0x0112, SHORT, count 1
  tiff += std::string(1, static_cast<char>(orientation)) + std::string("\0\0\0", 3);
  tiff += std::string("\0\0\0\0", 4);  // no next IFD
  const std::string body = std::string("Exif\0\0", 6) + tiff;
  const size_t length = body.size() + 2;
  const std::string app1 = std::string("\xFF\xE1", 2) + static_cast<char>(length >> 8) +
                           static_cast<char>(length & 0xFF) + body;
  const std::string path = dir + "/o" + std::to_string(orientation) + ".jpg";
  EXPECT_TRUE(WriteStringToFileAtomic(path, jpeg.substr(0, 2) + app1 + jpeg.substr(2)).ok());
  return path;
}

}  // namespace mgsr::testing
