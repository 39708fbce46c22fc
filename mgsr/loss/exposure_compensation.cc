#include "mgsr/loss/exposure_compensation.h"

#include <algorithm>
#include <cstdint>
#include <vector>

#include "mgsr/loss/loss_util.h"
#include "mgsr/loss/parallel_pixels.h"

namespace mgsr {

Status ParseExposureMode(const std::string& name, ExposureMode* mode) {
  if (name == "off") {
    *mode = ExposureMode::kOff;
  } else if (name == "diag") {
    *mode = ExposureMode::kDiagonal;
  } else if (name == "affine") {
    *mode = ExposureMode::kAffine;
  } else {
    return Status::Error("--exposure: '" + name + "' is not one of off, diag, affine");
  }
  return Status::Ok();
}

const char* ExposureModeName(ExposureMode mode) {
  switch (mode) {
    case ExposureMode::kOff:
      return "off";
    case ExposureMode::kDiagonal:
      return "diag";
    case ExposureMode::kAffine:
      return "affine";
  }
  return "?";
}

ColorTransform IdentityColorTransform() { return {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0}; }

bool ColorTransformParameterIsFree(ExposureMode mode, int index) {
  switch (mode) {
    case ExposureMode::kOff:
      return false;
    case ExposureMode::kDiagonal:
      return index == 0 || index == 4 || index == 8 || index >= 9;
    case ExposureMode::kAffine:
      return true;
  }
  return false;
}

template <typename T>
void ApplyColorTransform(const ColorTransform& p, const ImageT<T>& in, const ImageT<T>* mask,
                         ImageT<T>* out) {
  if (!out->SameShape(in)) *out = ImageT<T>(in.width(), in.height(), 3);
  const size_t n = in.plane_size();
  // Plain pointers and, below, two loops: the vectoriser takes neither a pointer loaded from an
  // array inside the loop nor the mask loaded under a condition (both had kept this loop scalar).
  const T *c0 = in.plane(0), *c1 = in.plane(1), *c2 = in.plane(2);
  const T* m = mask != nullptr ? mask->plane(0) : nullptr;
  for (int o = 0; o < 3; ++o) {
    const T a0 = static_cast<T>(p[3 * o]), a1 = static_cast<T>(p[3 * o + 1]),
            a2 = static_cast<T>(p[3 * o + 2]), b = static_cast<T>(p[9 + o]);
    T* dst = out->plane(o);
    const int64_t count = static_cast<int64_t>(n);
    const T* co = in.plane(o);
    if (m != nullptr) {
#pragma omp parallel for simd schedule(static) if (count >= kParallelPixels)
      for (int64_t i = 0; i < count; ++i) {
        const T mapped = a0 * c0[i] + a1 * c1[i] + a2 * c2[i] + b;
        dst[i] = m[i] * mapped + (T(1) - m[i]) * co[i];
      }
    } else {
#pragma omp parallel for simd schedule(static) if (count >= kParallelPixels)
      for (int64_t i = 0; i < count; ++i) dst[i] = a0 * c0[i] + a1 * c1[i] + a2 * c2[i] + b;
    }
  }
}

namespace {

// Channel k of pixel i adds o = 0, 1, 2 in turn: g_o (w A_ok + [o == k] (1 - w)), A = a (row o).
template <typename T>
inline void ColorTransformPixelBackward(const T* a, const T* g0, const T* g1, const T* g2, T w,
                                        int64_t i, T* dc0, T* dc1, T* dc2) {
  const T keep = T(1) - w;
  dc0[i] = ((dc0[i] + g0[i] * (w * a[0] + keep)) + g1[i] * (w * a[3] + T(0))) +
           g2[i] * (w * a[6] + T(0));
  dc1[i] = ((dc1[i] + g0[i] * (w * a[1] + T(0))) + g1[i] * (w * a[4] + keep)) +
           g2[i] * (w * a[7] + T(0));
  dc2[i] = ((dc2[i] + g0[i] * (w * a[2] + T(0))) + g1[i] * (w * a[5] + T(0))) +
           g2[i] * (w * a[8] + keep);
}

// Pixels per chunk of the backward pass: each chunk takes its twelve parameter sums in one read
// of its pixels, and the chunks' sums are added in chunk order, so they do not depend on the
// number of threads.
constexpr int64_t kTransformChunk = 32768;

// Pixels [begin, end): the colour's gradient and the twelve parameter sums, accumulated in double:
// sums[4 o + k] = sum_i g_o w c_k (k < 3) and sum_i g_o w (k = 3), w = the mask or 1.
template <typename T, bool kMasked>
void ColorTransformChunkBackward(const T* a, const T* const* c, const T* m, const T* const* g,
                                 T* const* dc, int64_t begin, int64_t end, double sums[12]) {
  const T *c0 = c[0], *c1 = c[1], *c2 = c[2], *g0 = g[0], *g1 = g[1], *g2 = g[2];
  T *dc0 = dc[0], *dc1 = dc[1], *dc2 = dc[2];
  double s00 = 0, s01 = 0, s02 = 0, s03 = 0, s10 = 0, s11 = 0, s12 = 0, s13 = 0, s20 = 0, s21 = 0,
         s22 = 0, s23 = 0;
#pragma omp simd reduction(+ : s00, s01, s02, s03, s10, s11, s12, s13, s20, s21, s22, s23)
  for (int64_t i = begin; i < end; ++i) {
    const T w = kMasked ? m[i] : T(1);
    ColorTransformPixelBackward(a, g0, g1, g2, w, i, dc0, dc1, dc2);
    const T gw0 = g0[i] * w, gw1 = g1[i] * w, gw2 = g2[i] * w;
    s00 += static_cast<double>(gw0 * c0[i]);
    s01 += static_cast<double>(gw0 * c1[i]);
    s02 += static_cast<double>(gw0 * c2[i]);
    s03 += static_cast<double>(gw0);
    s10 += static_cast<double>(gw1 * c0[i]);
    s11 += static_cast<double>(gw1 * c1[i]);
    s12 += static_cast<double>(gw1 * c2[i]);
    s13 += static_cast<double>(gw1);
    s20 += static_cast<double>(gw2 * c0[i]);
    s21 += static_cast<double>(gw2 * c1[i]);
    s22 += static_cast<double>(gw2 * c2[i]);
    s23 += static_cast<double>(gw2);
  }
  const double all[12] = {s00, s01, s02, s03, s10, s11, s12, s13, s20, s21, s22, s23};
  for (int j = 0; j < 12; ++j) sums[j] = all[j];
}

}  // namespace

template <typename T>
void ColorTransformBackward(const ColorTransform& p, const ImageT<T>& in, const ImageT<T>* mask,
                            const ImageT<T>& d_out, ImageT<T>* d_in, ColorTransform* d_params) {
  const T* m = mask != nullptr ? mask->plane(0) : nullptr;
  // d out_o / d c_k = m A_ok + (1 - m) [o == k];  d out_o / d A_ok = m c_k;  d out_o / d b_o = m.
  // One pass over the planes: each chunk of pixels adds its colour gradient and its parameter
  // sums (which had taken twelve passes).
  const int64_t count = static_cast<int64_t>(in.plane_size());
  const int64_t chunks = (count + kTransformChunk - 1) / kTransformChunk;
  const T* c[3] = {in.plane(0), in.plane(1), in.plane(2)};
  const T* g[3] = {d_out.plane(0), d_out.plane(1), d_out.plane(2)};
  T* dc[3] = {d_in->plane(0), d_in->plane(1), d_in->plane(2)};
  T a[9];
  for (int j = 0; j < 9; ++j) a[j] = static_cast<T>(p[j]);
  // resize() keeps the capacity: nothing is allocated once a size has been seen.
  static thread_local std::vector<double> chunk_sums;
  chunk_sums.resize(12 * static_cast<size_t>(chunks));
  double* sums = chunk_sums.data();  // a pointer, not the thread_local, into the region
#pragma omp parallel for schedule(dynamic) if (count >= kParallelPixels)
  for (int64_t k = 0; k < chunks; ++k) {
    const int64_t begin = k * kTransformChunk, end = std::min(count, begin + kTransformChunk);
    if (m != nullptr) {
      ColorTransformChunkBackward<T, true>(a, c, m, g, dc, begin, end, sums + 12 * k);
    } else {
      ColorTransformChunkBackward<T, false>(a, c, m, g, dc, begin, end, sums + 12 * k);
    }
  }
  double total[12] = {};
  for (int64_t k = 0; k < chunks; ++k) {
    for (int j = 0; j < 12; ++j) total[j] += sums[12 * k + j];
  }
  for (int o = 0; o < 3; ++o) {
    for (int k = 0; k < 3; ++k) (*d_params)[3 * o + k] += total[4 * o + k];
    (*d_params)[9 + o] += total[4 * o + 3];
  }
}

Status ExposureCompensatedLoss::Check(const RenderBuffers& in, const Targets& t) const {
  MGSR_RETURN_IF_ERROR(RequireImage(Name(), BufferName(Buffer::kColor), in.Get(Buffer::kColor),
                                    static_cast<const Image*>(nullptr), 3));
  if (t.mask != nullptr) {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), "mask", t.mask, in.Get(Buffer::kColor), 1));
  }
  return inner_->Check(in, t);
}

template <typename T>
double ExposureCompensatedLoss::Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t,
                                        double scale, RenderGradientsT<T>* grad) const {
  const ImageT<T>& color = *in.Get(Buffer::kColor);
  Scratch<T>& scratch = ScratchFor<T>();
  ImageT<T>& mapped = scratch.mapped;
  ApplyColorTransform(transform_, color, t.mask, &mapped);
  RenderBuffersT<T> inner_in = in;
  inner_in.Set(Buffer::kColor, &mapped);
  parameter_gradient_ = ColorTransform{};
  if (grad == nullptr) return inner_->Evaluate(inner_in, t, scale, nullptr);

  RenderGradientsT<T>& inner_grad = scratch.inner_grad;
  inner_grad.Clear();
  const double value = inner_->Evaluate(inner_in, t, scale, &inner_grad);
  for (int b = 0; b < kNumBuffers; ++b) {
    const ImageT<T>& g = inner_grad.images[b];
    if (g.empty()) continue;
    if (static_cast<Buffer>(b) == Buffer::kColor) {
      ColorTransformBackward(transform_, color, t.mask, g, &grad->Get(Buffer::kColor, color),
                             &parameter_gradient_);
    } else {
      ImageT<T>& dst = grad->Get(static_cast<Buffer>(b), g);
      for (size_t i = 0; i < g.size(); ++i) dst.data()[i] += g.data()[i];
    }
  }
  return value;
}

template void ApplyColorTransform<float>(const ColorTransform&, const Image&, const Image*, Image*);
template void ApplyColorTransform<double>(const ColorTransform&, const ImageD&, const ImageD*,
                                          ImageD*);
template void ColorTransformBackward<float>(const ColorTransform&, const Image&, const Image*,
                                            const Image&, Image*, ColorTransform*);
template void ColorTransformBackward<double>(const ColorTransform&, const ImageD&, const ImageD*,
                                             const ImageD&, ImageD*, ColorTransform*);
template double ExposureCompensatedLoss::Compute<float>(const RenderBuffers&, const Targets&,
                                                        double, RenderGradients*) const;
template double ExposureCompensatedLoss::Compute<double>(const RenderBuffersD&, const TargetsD&,
                                                         double, RenderGradientsD*) const;

}  // namespace mgsr
