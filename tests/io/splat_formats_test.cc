#include "mgsr/io/splat_formats.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <map>

#include "mgsr/core/rng.h"
#include "mgsr/core/subprocess.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/model/activations.h"
#include "mgsr/render/sh.h"
#include "test_util.h"

namespace mgsr {
namespace {

// A model with every attribute in the ranges training produces (SH rest within [-1, 1], as the
// .spz quantiser assumes), distinct x coordinates to match splats after the .splat sort.
GaussianModel RandomModel(size_t n, int degree, uint64_t seed) {
  Rng rng(seed);
  GaussianModel m;
  m.max_sh_degree = degree;
  m.Resize(n);
  const int K = m.sh_coeffs();
  for (size_t i = 0; i < n; ++i) {
    m.means[i * 3 + 0] = -1.5f + 3.0f * (i + 0.5f) / n;
    m.means[i * 3 + 1] = rng.Uniform(-1.5f, 1.5f);
    m.means[i * 3 + 2] = rng.Uniform(-1.5f, 1.5f);
    for (int d = 0; d < 3; ++d) m.log_scales[i * 3 + d] = rng.Uniform(-6.0f, -1.0f);
    for (int d = 0; d < 4; ++d) m.quats[i * 4 + d] = rng.Uniform(-1.0f, 1.0f);
    m.opacity_logits[i] = rng.Uniform(-4.0f, 4.0f);
    for (int k = 0; k < K; ++k)
      for (int c = 0; c < 3; ++c) m.sh[(i * K + k) * 3 + c] = rng.Uniform(-0.9f, 0.9f);
  }
  return m;
}

// The colour (before the 0.5 offset) of splat i seen along `dir`.
float ShColor(const GaussianModel& m, size_t i, int c, const float dir[3]) {
  float b[kMaxShCoeffs];
  ShBasis(m.max_sh_degree, dir, b);
  float v = 0;
  for (int k = 0; k < m.sh_coeffs(); ++k) v += b[k] * m.sh[(i * m.sh_coeffs() + k) * 3 + c];
  return v;
}

// |cos| of the angle between two rotations given as quaternions (q and -q are one rotation).
float QuaternionAgreement(const float* a, const float* b) {
  float ua[4], ub[4], R[9];
  QuaternionToRotation(a, R, ua);
  QuaternionToRotation(b, R, ub);
  return std::abs(ua[0] * ub[0] + ua[1] * ub[1] + ua[2] * ub[2] + ua[3] * ub[3]);
}

TEST(SplatFormatsTest, SplatRoundTripKeepsWhatTheFormatHolds) {
  const std::string dir = testing::ScratchDir();
  const GaussianModel m = RandomModel(300, 3, 7);
  ASSERT_TRUE(WriteSplatFile(dir + "/m.splat", m).ok());
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(dir + "/m.splat", &bytes).ok());
  EXPECT_EQ(bytes.size(), 32u * m.size());
  GaussianModel back;
  ASSERT_TRUE(ReadSplatFile(dir + "/m.splat", &back).ok());
  ASSERT_EQ(back.size(), m.size());
  EXPECT_EQ(back.max_sh_degree, 0);
  std::map<float, size_t> by_x;
  for (size_t i = 0; i < m.size(); ++i) by_x[m.means[i * 3]] = i;
  float previous_importance = INFINITY;
  for (size_t j = 0; j < back.size(); ++j) {
    ASSERT_TRUE(by_x.count(back.means[j * 3]));
    const size_t i = by_x[back.means[j * 3]];
    for (int d = 0; d < 3; ++d) {
      EXPECT_EQ(back.means[j * 3 + d], m.means[i * 3 + d]);
      EXPECT_NEAR(back.log_scales[j * 3 + d], m.log_scales[i * 3 + d], 1e-5);
    }
    // Colour and opacity are bytes: within half a step of 1/255 after activation.
    for (int c = 0; c < 3; ++c) {
      const float want = std::clamp(0.5f + 0.2820948f * m.sh[i * 48 + c], 0.0f, 1.0f);
      EXPECT_NEAR(0.5f + 0.2820948f * back.sh[j * 3 + c], want, 0.5f / 255 + 1e-5);
    }
    EXPECT_NEAR(Sigmoid(back.opacity_logits[j]), Sigmoid(m.opacity_logits[i]), 0.5f / 255 + 1e-5);
    EXPECT_GT(QuaternionAgreement(&back.quats[j * 4], &m.quats[i * 4]), 0.999f);
    // Largest (scale volume x opacity, of the written model) first.
    const float* s = &m.log_scales[i * 3];
    const float importance = std::exp(s[0] + s[1] + s[2]) * Sigmoid(m.opacity_logits[i]);
    EXPECT_LE(importance, previous_importance);
    previous_importance = importance;
  }
}

TEST(SplatFormatsTest, SpzRoundTripWithinItsQuantisation) {
  const std::string dir = testing::ScratchDir();
  for (int degree : {0, 1, 3}) {
    SCOPED_TRACE(degree);
    const GaussianModel m = RandomModel(400, degree, 11 + degree);
    ASSERT_TRUE(WriteSpzFile(dir + "/m.spz", m).ok());
    GaussianModel back;
    ASSERT_TRUE(ReadSpzFile(dir + "/m.spz", &back).ok());
    ASSERT_EQ(back.size(), m.size());
    ASSERT_EQ(back.max_sh_degree, degree);
    const int K = m.sh_coeffs();
    for (size_t i = 0; i < m.size(); ++i) {
      for (int d = 0; d < 3; ++d) {
        EXPECT_NEAR(back.means[i * 3 + d], m.means[i * 3 + d], 0.5 / 4096 + 1e-6);
        EXPECT_NEAR(back.log_scales[i * 3 + d], m.log_scales[i * 3 + d], 0.5 / 16 + 1e-5);
        // DC as 0.5 + 0.15 f_dc in a byte.
        EXPECT_NEAR(back.sh[i * K * 3 + d], m.sh[i * K * 3 + d], 0.5 / 255 / 0.15 + 1e-5);
      }
      EXPECT_NEAR(Sigmoid(back.opacity_logits[i]), Sigmoid(m.opacity_logits[i]), 0.5 / 255 + 1e-5);
      // Smallest three at 9 bits: each within sqrt(1/2) / 1022 of the unit quaternion.
      EXPECT_GT(QuaternionAgreement(&back.quats[i * 4], &m.quats[i * 4]), 0.99999f);
      for (int k = 1; k < K; ++k) {
        // Rounded to 1/128, then to a bucket of 8 (5 bits) or 16 (4 bits) of those.
        const double step = k < 4 ? 8.0 / 128 : 16.0 / 128;
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(back.sh[(i * K + k) * 3 + c], m.sh[(i * K + k) * 3 + c],
                      step / 2 + 0.5 / 128 + 1e-5);
      }
    }
    // Seen from any direction the colour agrees to the SH quantisation.
    const float view[3] = {0.36f, -0.48f, 0.8f};
    for (size_t i = 0; i < m.size(); i += 37)
      EXPECT_NEAR(ShColor(back, i, 1, view), ShColor(m, i, 1, view), 0.15);
  }
}

// The .spz axes are right-up-back: a splat at (x, y, z) in our (COLMAP) axes is stored at
// (x, -y, -z), and the stored (right-up-back) SH seen along the flipped direction gives our colour.
TEST(SplatFormatsTest, SpzStoresRightUpBackAxes) {
  const std::string dir = testing::ScratchDir();
  GaussianModel m = RandomModel(1, 1, 3);
  m.means = {0.25f, 0.5f, -1.0f};
  ASSERT_TRUE(WriteSpzFile(dir + "/m.spz", m).ok());
  std::string file, raw(1 << 16, '\0');
  ASSERT_TRUE(ReadFileToString(dir + "/m.spz", &file).ok());
  z_stream z{};
  ASSERT_EQ(inflateInit2(&z, 16 + MAX_WBITS), Z_OK);
  z.next_in = reinterpret_cast<Bytef*>(&file[0]);
  z.avail_in = static_cast<uInt>(file.size());
  z.next_out = reinterpret_cast<Bytef*>(&raw[0]);
  z.avail_out = static_cast<uInt>(raw.size());
  ASSERT_EQ(inflate(&z, Z_FINISH), Z_STREAM_END);
  raw.resize(z.total_out);
  inflateEnd(&z);
  const auto* p = reinterpret_cast<const unsigned char*>(raw.data());
  ASSERT_EQ(raw.size(), 16u + 9 + 1 + 3 + 3 + 4 + 9);
  EXPECT_EQ(p[0] | p[1] << 8 | p[2] << 16 | p[3] << 24, 0x5053474e);
  EXPECT_EQ(p[4], 3);   // version
  EXPECT_EQ(p[12], 1);  // SH degree
  const int bits = p[13];
  EXPECT_EQ(bits, 12);
  const float want[3] = {0.25f, -0.5f, 1.0f};
  for (int d = 0; d < 3; ++d) {
    const unsigned char* b = p + 16 + 3 * d;
    int32_t v = b[0] | b[1] << 8 | b[2] << 16;
    if (v & 0x800000) v -= 0x1000000;
    EXPECT_FLOAT_EQ(v / 4096.0f, want[d]);
  }
  // Degree-1 SH bytes (after position 9, alpha 1, colour 3, scale 3, rotation 4): the stored
  // coefficients evaluated along (x, -y, -z) give our colour along (x, y, z).
  const unsigned char* sh = p + 16 + 20;
  const float d[3] = {0.48f, 0.6f, 0.64f}, flipped[3] = {d[0], -d[1], -d[2]};
  float b[kMaxShCoeffs], bf[kMaxShCoeffs];
  ShBasis(1, d, b);
  ShBasis(1, flipped, bf);
  for (int c = 0; c < 3; ++c) {
    float ours = 0, stored = 0;
    for (int k = 1; k < 4; ++k) {
      ours += b[k] * m.sh[k * 3 + c];
      stored += bf[k] * (sh[(k - 1) * 3 + c] - 128.0f) / 128.0f;
    }
    EXPECT_NEAR(stored, ours, 0.05);
  }
}

TEST(SplatFormatsTest, BadFilesGiveOneLineErrors) {
  const std::string dir = testing::ScratchDir();
  GaussianModel m;
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/odd.splat", std::string(33, 'x')).ok());
  Status s = ReadSplatFile(dir + "/odd.splat", &m);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("odd.splat"), std::string::npos);
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/plain.spz", "not gzip at all").ok());
  s = ReadSpzFile(dir + "/plain.spz", &m);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("plain.spz"), std::string::npos);
  // A valid stream cut short: the header promises more splats than follow.
  ASSERT_TRUE(WriteSpzFile(dir + "/m.spz", RandomModel(50, 2, 5)).ok());
  std::string file;
  ASSERT_TRUE(ReadFileToString(dir + "/m.spz", &file).ok());
  ASSERT_TRUE(WriteStringToFileAtomic(dir + "/cut.spz", file.substr(0, file.size() / 2)).ok());
  s = ReadSpzFile(dir + "/cut.spz", &m);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("cut.spz"), std::string::npos);
  EXPECT_EQ(s.message().find('\n'), std::string::npos);
}

TEST(SplatFormatsTest, ExportListIsChecked) {
  std::vector<std::string> f;
  ASSERT_TRUE(ParseExportFormats("ply, splat,spz,ply", &f).ok());
  EXPECT_EQ(f, (std::vector<std::string>{"ply", "splat", "spz"}));
  ASSERT_TRUE(ParseExportFormats("glb,ply", &f).ok());
  EXPECT_EQ(f, (std::vector<std::string>{"glb", "ply"}));
  EXPECT_FALSE(ParseExportFormats("ply,obj", &f).ok());
  EXPECT_FALSE(ParseExportFormats(" , ", &f).ok());
}

// ---- Against a third-party reader: PlayCanvas' splat-transform (npm, pinned in
// tests/third_party/package.json; scripts/install_npm_tools.sh puts it under the build folder).

std::string SplatTransform() {
  const std::string path = std::string(MGSR_NPM_TOOLS_DIR) + "/node_modules/.bin/splat-transform";
  return FileExists(path) ? path : "";
}

#define REQUIRE_SPLAT_TRANSFORM(tool)                                                      \
  const std::string tool = SplatTransform();                                               \
  if (tool.empty())                                                                        \
  GTEST_SKIP() << "splat-transform is not installed under " MGSR_NPM_TOOLS_DIR             \
                  " (bash scripts/install_npm_tools.sh installs it; it needs npm and the " \
                  "npm registry)"

// Runs splat-transform IN OUT [args...]; its output goes to `dir`/splat_transform.log.
void Convert(const std::string& tool, const std::string& dir, const std::string& in,
             const std::string& out, const std::vector<std::string>& args = {}) {
  std::vector<std::string> argv = {tool, "-w", "-q", in, out};
  argv.insert(argv.end(), args.begin(), args.end());
  const ProgramResult r = RunProgram(argv, {}, dir + "/splat_transform.log", 120);
  ASSERT_TRUE(r.started && r.exit_code == 0)
      << "splat-transform " << in << " " << out << " failed; see " << dir << "/splat_transform.log";
}

// Every standard 3DGS attribute of `got` within the given tolerances of `want` (same order).
void ExpectSameSplats(const GaussianModel& got, const GaussianModel& want, double position,
                      double log_scale, double alpha, double dc, double sh_rest, float rotation) {
  ASSERT_EQ(got.size(), want.size());
  ASSERT_EQ(got.max_sh_degree, want.max_sh_degree);
  const int K = want.sh_coeffs();
  int bad = 0;
  for (size_t i = 0; i < want.size() && bad < 10; ++i) {
    for (int d = 0; d < 3; ++d) {
      bad += std::abs(got.means[i * 3 + d] - want.means[i * 3 + d]) > position;
      bad += std::abs(got.log_scales[i * 3 + d] - want.log_scales[i * 3 + d]) > log_scale;
    }
    bad += std::abs(Sigmoid(got.opacity_logits[i]) - Sigmoid(want.opacity_logits[i])) > alpha;
    bad += QuaternionAgreement(&got.quats[i * 4], &want.quats[i * 4]) < rotation;
    for (int k = 0; k < K; ++k) {
      for (int c = 0; c < 3; ++c) {
        const float e = std::abs(got.sh[(i * K + k) * 3 + c] - want.sh[(i * K + k) * 3 + c]);
        bad += e > (k == 0 ? dc : sh_rest);
      }
    }
    EXPECT_EQ(bad, 0) << "splat " << i;
  }
}

TEST(SplatTransformInteropTest, ReadsOurPlyAsWeWroteIt) {
  REQUIRE_SPLAT_TRANSFORM(tool);
  const std::string dir = testing::ScratchDir();
  const GaussianModel m = RandomModel(500, 3, 21);
  ASSERT_TRUE(WriteGaussianPly(dir + "/ours.ply", m).ok());
  Convert(tool, dir, dir + "/ours.ply", dir + "/theirs.ply");
  GaussianModel back;
  ASSERT_TRUE(ReadGaussianPly(dir + "/theirs.ply", &back).ok());
  ExpectSameSplats(back, m, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 0.999999f);
}

TEST(SplatTransformInteropTest, ReadsOurSpzAsOurModel) {
  REQUIRE_SPLAT_TRANSFORM(tool);
  const std::string dir = testing::ScratchDir();
  const GaussianModel m = RandomModel(500, 3, 22);
  ASSERT_TRUE(WriteSpzFile(dir + "/ours.spz", m).ok());
  Convert(tool, dir, dir + "/ours.spz", dir + "/theirs.ply");
  GaussianModel back;
  ASSERT_TRUE(ReadGaussianPly(dir + "/theirs.ply", &back).ok());
  // Within the format's quantisation (SpzRoundTripWithinItsQuantisation), in our axes again.
  ExpectSameSplats(back, m, 0.5 / 4096 + 1e-6, 0.5 / 16 + 1e-5, 0.5 / 255 + 1e-5,
                   0.5 / 255 / 0.15 + 1e-5, 8.0 / 128 + 0.5 / 128 + 1e-5, 0.99999f);
}

TEST(SplatTransformInteropTest, WritesTheSpzWeWrite) {
  REQUIRE_SPLAT_TRANSFORM(tool);
  const std::string dir = testing::ScratchDir();
  const GaussianModel m = RandomModel(500, 3, 23);
  ASSERT_TRUE(WriteGaussianPly(dir + "/ours.ply", m).ok());
  ASSERT_TRUE(WriteSpzFile(dir + "/ours.spz", m).ok());
  Convert(tool, dir, dir + "/ours.ply", dir + "/theirs.spz", {"--spz-version", "3"});
  GaussianModel ours, theirs;
  ASSERT_TRUE(ReadSpzFile(dir + "/ours.spz", &ours).ok());
  ASSERT_TRUE(ReadSpzFile(dir + "/theirs.spz", &theirs).ok());
  // The same bytes, so the same decoded values (at most one quantisation step apart on a tie).
  ExpectSameSplats(theirs, ours, 1.0 / 4096 + 1e-6, 1.0 / 16 + 1e-5, 1.0 / 255 + 1e-5,
                   1.0 / 255 / 0.15 + 1e-5, 16.0 / 128 + 1e-5, 0.9999f);
}

TEST(SplatTransformInteropTest, ReadsOurSplat) {
  REQUIRE_SPLAT_TRANSFORM(tool);
  const std::string dir = testing::ScratchDir();
  GaussianModel m = RandomModel(500, 0, 24);
  ASSERT_TRUE(WriteSplatFile(dir + "/ours.splat", m).ok());
  Convert(tool, dir, dir + "/ours.splat", dir + "/theirs.ply");
  GaussianModel back, ours;
  ASSERT_TRUE(ReadGaussianPly(dir + "/theirs.ply", &back).ok());
  ASSERT_TRUE(ReadSplatFile(dir + "/ours.splat", &ours).ok());
  // Both readers decode the file alike (same order: the file's).
  ExpectSameSplats(back, ours, 1e-6, 1e-5, 1e-3, 1e-3, 0, 0.9999f);
}

}  // namespace
}  // namespace mgsr
