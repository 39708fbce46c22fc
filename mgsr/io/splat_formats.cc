#include "mgsr/io/splat_formats.h"

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <sstream>

#include "mgsr/io/file_util.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/model/activations.h"
#include "mgsr/model/init_from_points.h"
#include "mgsr/render/sh.h"

namespace mgsr {
namespace {

constexpr size_t kSplatBytes = 32;
constexpr uint32_t kSpzMagic = 0x5053474e;  // "NGSP"
constexpr uint32_t kSpzVersion = 3;
constexpr size_t kSpzHeaderBytes = 16;
constexpr int kSpzFractionalBits = 12;  // 1/4096 of a unit, unless the scene is too large for it
constexpr float kSpzColorScale = 0.15f;
constexpr float kSqrtHalf = 0.70710678118654752f;

uint8_t ToByte(float x) { return static_cast<uint8_t>(std::clamp(std::round(x), 0.0f, 255.0f)); }

void PutU32(std::string* out, uint32_t v) {
  for (int b = 0; b < 4; ++b) out->push_back(static_cast<char>((v >> (8 * b)) & 0xff));
}
void PutF32(std::string* out, float f) {
  uint32_t bits;
  std::memcpy(&bits, &f, 4);
  PutU32(out, bits);
}
uint32_t GetU32(const unsigned char* p) {
  return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
}
float GetF32(const unsigned char* p) {
  const uint32_t bits = GetU32(p);
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

// The normalised quaternion (w, x, y, z) of splat i (identity for a zero one).
void UnitQuaternion(const GaussianModel& m, size_t i, float q[4]) {
  float R[9];
  QuaternionToRotation(&m.quats[i * 4], R, q);
}

// A decoded opacity byte as a logit; 0 and 255 are kept finite.
float OpacityLogitFromByte(uint8_t a) {
  return InverseSigmoid(std::clamp(a / 255.0f, 0.5f / 255.0f, 254.5f / 255.0f));
}

// Sign of each SH basis function when y and z flip (right-down-forward <-> right-up-back): from
// the basis itself at a generic direction, so it follows whatever convention sh.cc uses.
void ShFlipSigns(float sign[kMaxShCoeffs]) {
  const float d[3] = {0.48f, 0.6f, 0.64f}, flipped[3] = {d[0], -d[1], -d[2]};
  float b[kMaxShCoeffs], bf[kMaxShCoeffs];
  ShBasis(3, d, b);
  ShBasis(3, flipped, bf);
  for (int k = 0; k < kMaxShCoeffs; ++k) sign[k] = bf[k] * b[k] < 0 ? -1.0f : 1.0f;
}

Status Gzip(const std::string& in, std::string* out) {
  z_stream z{};
  if (deflateInit2(&z, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 9, Z_DEFAULT_STRATEGY) !=
      Z_OK)
    return Status::Error("zlib: deflateInit2 failed");
  out->resize(deflateBound(&z, in.size()));
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  z.avail_in = static_cast<uInt>(in.size());
  z.next_out = reinterpret_cast<Bytef*>(&(*out)[0]);
  z.avail_out = static_cast<uInt>(out->size());
  const int r = deflate(&z, Z_FINISH);
  out->resize(z.total_out);
  deflateEnd(&z);
  return r == Z_STREAM_END ? Status::Ok() : Status::Error("zlib: deflate failed");
}

Status Gunzip(const std::string& path, const std::string& in, std::string* out) {
  z_stream z{};
  if (inflateInit2(&z, 16 + MAX_WBITS) != Z_OK) return Status::Error("zlib: inflateInit2 failed");
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
  z.avail_in = static_cast<uInt>(in.size());
  out->clear();
  char buffer[1 << 16];
  int r = Z_OK;
  while (r == Z_OK) {
    z.next_out = reinterpret_cast<Bytef*>(buffer);
    z.avail_out = sizeof(buffer);
    r = inflate(&z, Z_NO_FLUSH);
    out->append(buffer, sizeof(buffer) - z.avail_out);
  }
  inflateEnd(&z);
  if (r != Z_STREAM_END) return Status::Error(path + ": not a complete gzip stream");
  return Status::Ok();
}

}  // namespace

Status WriteSplatFile(const std::string& path, const GaussianModel& m) {
  const size_t n = m.size();
  const int K = m.sh_coeffs();
  std::vector<float> importance(n);
  for (size_t i = 0; i < n; ++i) {
    const float* s = &m.log_scales[i * 3];
    importance[i] = std::exp(s[0] + s[1] + s[2]) * Sigmoid(m.opacity_logits[i]);
  }
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return importance[a] > importance[b]; });
  std::string out;
  out.reserve(n * kSplatBytes);
  for (size_t i : order) {
    for (int d = 0; d < 3; ++d) PutF32(&out, m.means[i * 3 + d]);
    for (int d = 0; d < 3; ++d) PutF32(&out, std::exp(m.log_scales[i * 3 + d]));
    for (int c = 0; c < 3; ++c) out.push_back(ToByte((0.5f + kShC0 * m.sh[i * K * 3 + c]) * 255));
    out.push_back(ToByte(Sigmoid(m.opacity_logits[i]) * 255));
    float q[4];
    UnitQuaternion(m, i, q);
    for (int k = 0; k < 4; ++k) out.push_back(ToByte(q[k] * 128 + 128));
  }
  return WriteStringToFileAtomic(path, out);
}

Status ReadSplatFile(const std::string& path, GaussianModel* model) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  if (data.empty() || data.size() % kSplatBytes != 0)
    return Status::Error(path + ": a .splat file is a whole number of 32-byte splats, not " +
                         std::to_string(data.size()) + " bytes");
  GaussianModel m;
  m.max_sh_degree = 0;
  m.Resize(data.size() / kSplatBytes);
  const auto* p = reinterpret_cast<const unsigned char*>(data.data());
  for (size_t i = 0; i < m.size(); ++i, p += kSplatBytes) {
    for (int d = 0; d < 3; ++d) {
      const float x = GetF32(p + 4 * d), s = GetF32(p + 12 + 4 * d);
      if (!std::isfinite(x) || !(s > 0) || !std::isfinite(s))
        return Status::Error(path + ": bad position or scale at splat " + std::to_string(i));
      m.means[i * 3 + d] = x;
      m.log_scales[i * 3 + d] = std::log(s);
    }
    for (int c = 0; c < 3; ++c) m.sh[i * 3 + c] = (p[24 + c] / 255.0f - 0.5f) / kShC0;
    m.opacity_logits[i] = OpacityLogitFromByte(p[27]);
    for (int k = 0; k < 4; ++k) m.quats[i * 4 + k] = (p[28 + k] - 128.0f) / 128.0f;
  }
  SetPlainReflection(&m);
  *model = std::move(m);
  return Status::Ok();
}

Status WriteSpzFile(const std::string& path, const GaussianModel& m) {
  const size_t n = m.size();
  const int K = m.sh_coeffs();
  if (n > 0xffffffffu) return Status::Error(path + ": too many splats for .spz");
  // 24-bit positions: 12 fractional bits (0.25 mm in metres), fewer when the scene is larger than
  // +-2048 units.
  float extent = 0;
  for (float x : m.means) extent = std::max(extent, std::abs(x));
  int fractional_bits = kSpzFractionalBits;
  while (fractional_bits > 0 && extent * float(1 << fractional_bits) >= float((1 << 23) - 1))
    --fractional_bits;
  if (extent * float(1 << fractional_bits) >= float((1 << 23) - 1))
    return Status::Error(path + ": positions beyond +-8 million units do not fit .spz");
  const float flip_p[3] = {1, -1, -1};
  float flip_sh[kMaxShCoeffs];
  ShFlipSigns(flip_sh);

  std::string raw;
  raw.reserve(kSpzHeaderBytes + n * (9 + 1 + 3 + 3 + 4 + (K - 1) * 3));
  PutU32(&raw, kSpzMagic);
  PutU32(&raw, kSpzVersion);
  PutU32(&raw, static_cast<uint32_t>(n));
  raw.push_back(static_cast<char>(m.max_sh_degree));
  raw.push_back(static_cast<char>(fractional_bits));
  raw.push_back(0);  // flags: not trained with the antialiasing filter of Mip-Splatting
  raw.push_back(0);  // reserved
  const float unit = float(1 << fractional_bits);
  for (size_t i = 0; i < n; ++i) {
    for (int d = 0; d < 3; ++d) {
      const int32_t fixed =
          static_cast<int32_t>(std::lround(flip_p[d] * m.means[i * 3 + d] * unit));
      for (int b = 0; b < 3; ++b) raw.push_back(static_cast<char>((fixed >> (8 * b)) & 0xff));
    }
  }
  for (size_t i = 0; i < n; ++i) raw.push_back(ToByte(Sigmoid(m.opacity_logits[i]) * 255));
  for (size_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c)
      raw.push_back(ToByte(m.sh[i * K * 3 + c] * (kSpzColorScale * 255) + 0.5f * 255));
  }
  for (size_t i = 0; i < n * 3; ++i) raw.push_back(ToByte((m.log_scales[i] + 10) * 16));
  for (size_t i = 0; i < n; ++i) {
    float wxyz[4];
    UnitQuaternion(m, i, wxyz);
    // .spz orders the quaternion (x, y, z, w); flipping y and z conjugates the rotation by a half
    // turn about x, which negates the quaternion's y and z.
    const float q[4] = {wxyz[1], -wxyz[2], -wxyz[3], wxyz[0]};
    int largest = 0;
    for (int k = 1; k < 4; ++k)
      if (std::abs(q[k]) > std::abs(q[largest])) largest = k;
    const bool negate = q[largest] < 0;  // q and -q are one rotation: make the largest positive
    uint32_t packed = static_cast<uint32_t>(largest);
    for (int k = 0; k < 4; ++k) {
      if (k == largest) continue;
      const uint32_t sign = (q[k] < 0) != negate ? 1u : 0u;
      const uint32_t magnitude = static_cast<uint32_t>(
          std::min(511.0f, std::floor(511.0f * std::abs(q[k]) / kSqrtHalf + 0.5f)));
      packed = packed << 10 | sign << 9 | magnitude;
    }
    PutU32(&raw, packed);
  }
  for (size_t i = 0; i < n; ++i) {
    for (int k = 1; k < K; ++k) {
      const int bucket = k < 4 ? 8 : 16;  // 5 bits of precision for degree 1, 4 above
      for (int c = 0; c < 3; ++c) {
        int q = static_cast<int>(std::lround(flip_sh[k] * m.sh[(i * K + k) * 3 + c] * 128)) + 128;
        q = (q + bucket / 2) / bucket * bucket;
        raw.push_back(static_cast<char>(std::clamp(q, 0, 255)));
      }
    }
  }
  std::string compressed;
  MGSR_RETURN_IF_ERROR(Gzip(raw, &compressed));
  return WriteStringToFileAtomic(path, compressed);
}

Status ReadSpzFile(const std::string& path, GaussianModel* model) {
  std::string file, raw;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &file));
  MGSR_RETURN_IF_ERROR(Gunzip(path, file, &raw));
  if (raw.size() < kSpzHeaderBytes) return Status::Error(path + ": .spz header is cut short");
  const auto* p = reinterpret_cast<const unsigned char*>(raw.data());
  const uint32_t magic = GetU32(p), version = GetU32(p + 4), n = GetU32(p + 8);
  const int degree = p[12], fractional_bits = p[13];
  if (magic != kSpzMagic) return Status::Error(path + ": not a .spz file (bad magic)");
  if (version != 2 && version != 3)
    return Status::Error(path + ": .spz version " + std::to_string(version) +
                         " is not supported (2 and 3 are)");
  if (degree > 3)
    return Status::Error(path + ": SH degree " + std::to_string(degree) + " (at most 3)");
  if (fractional_bits > 23) return Status::Error(path + ": bad fractional bits");
  GaussianModel m;
  m.max_sh_degree = degree;
  const int K = m.sh_coeffs();
  const size_t rot_bytes = version >= 3 ? 4 : 3;
  const size_t need = kSpzHeaderBytes + size_t{n} * (9 + 1 + 3 + 3 + rot_bytes + (K - 1) * 3);
  if (raw.size() < need)
    return Status::Error(path + ": .spz data is cut short (" + std::to_string(raw.size()) +
                         " bytes, " + std::to_string(need) + " needed for " + std::to_string(n) +
                         " splats)");
  m.Resize(n);
  const float flip_p[3] = {1, -1, -1};
  float flip_sh[kMaxShCoeffs];
  ShFlipSigns(flip_sh);
  const unsigned char* pos = p + kSpzHeaderBytes;
  const unsigned char* alpha = pos + size_t{n} * 9;
  const unsigned char* color = alpha + n;
  const unsigned char* scale = color + size_t{n} * 3;
  const unsigned char* rot = scale + size_t{n} * 3;
  const unsigned char* sh = rot + size_t{n} * rot_bytes;
  const float unit = 1.0f / float(1 << fractional_bits);
  for (size_t i = 0; i < n; ++i) {
    for (int d = 0; d < 3; ++d) {
      const unsigned char* b = pos + i * 9 + d * 3;
      int32_t fixed = int32_t{b[0]} | int32_t{b[1]} << 8 | int32_t{b[2]} << 16;
      if (fixed & 0x800000) fixed -= 0x1000000;  // sign of the 24-bit value
      m.means[i * 3 + d] = flip_p[d] * fixed * unit;
      m.log_scales[i * 3 + d] = scale[i * 3 + d] / 16.0f - 10;
      m.sh[i * K * 3 + d] = (color[i * 3 + d] / 255.0f - 0.5f) / kSpzColorScale;
    }
    m.opacity_logits[i] = OpacityLogitFromByte(alpha[i]);
    float q[4] = {0, 0, 0, 0};  // x, y, z, w
    if (version >= 3) {
      uint32_t packed = GetU32(rot + i * 4);
      const int largest = static_cast<int>(packed >> 30);
      float sum = 0;
      for (int k = 3; k >= 0; --k) {  // packed first-to-last, so unpacked last-to-first
        if (k == largest) continue;
        const float v = kSqrtHalf * float(packed & 511u) / 511.0f;
        q[k] = (packed >> 9 & 1u) ? -v : v;
        sum += v * v;
        packed >>= 10;
      }
      q[largest] = std::sqrt(std::max(0.0f, 1 - sum));
    } else {
      float sum = 0;
      for (int k = 0; k < 3; ++k) {
        q[k] = rot[i * 3 + k] / 127.5f - 1;
        sum += q[k] * q[k];
      }
      q[3] = std::sqrt(std::max(0.0f, 1 - sum));
    }
    const float wxyz[4] = {q[3], q[0], -q[1], -q[2]};
    std::copy(wxyz, wxyz + 4, &m.quats[i * 4]);
    for (int k = 1; k < K; ++k) {
      for (int c = 0; c < 3; ++c) {
        const uint8_t b = sh[(i * (K - 1) + (k - 1)) * 3 + c];
        m.sh[(i * K + k) * 3 + c] = flip_sh[k] * (b - 128.0f) / 128.0f;
      }
    }
  }
  SetPlainReflection(&m);
  *model = std::move(m);
  return Status::Ok();
}

Status ParseExportFormats(const std::string& list, std::vector<std::string>* formats) {
  formats->clear();
  std::stringstream in(list);
  std::string item;
  while (std::getline(in, item, ',')) {
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    if (item.empty()) continue;
    if (item != "ply" && item != "splat" && item != "spz" && item != "glb")
      return Status::Error("--export: unknown format '" + item + "' (ply, splat, spz, glb)");
    if (std::find(formats->begin(), formats->end(), item) == formats->end())
      formats->push_back(item);
  }
  if (formats->empty()) return Status::Error("--export: name at least one of ply, splat, spz, glb");
  return Status::Ok();
}

}  // namespace mgsr
