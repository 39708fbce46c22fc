#include "mgsr/loss/exposure_compensation.h"

#include <cstdint>

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

// sum_i g_i w_i c_i and sum_i g_i w_i (w = the mask, or 1), accumulated in double.
template <typename T>
double WeightedDot(const T* g, const T* m, const T* c, size_t n) {
  double s = 0;
#pragma omp simd reduction(+ : s)
  for (size_t i = 0; i < n; ++i) {
    const T w = m != nullptr ? m[i] : T(1);
    s += static_cast<double>(g[i] * w * c[i]);
  }
  return s;
}
template <typename T>
double WeightedSum(const T* g, const T* m, size_t n) {
  double s = 0;
#pragma omp simd reduction(+ : s)
  for (size_t i = 0; i < n; ++i) s += static_cast<double>(m != nullptr ? g[i] * m[i] : g[i]);
  return s;
}

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

}  // namespace

template <typename T>
void ColorTransformBackward(const ColorTransform& p, const ImageT<T>& in, const ImageT<T>* mask,
                            const ImageT<T>& d_out, ImageT<T>* d_in, ColorTransform* d_params) {
  const size_t n = in.plane_size();
  const T* m = mask != nullptr ? mask->plane(0) : nullptr;
  ColorTransform dp{};
  // d out_o / d c_k = m A_ok + (1 - m) [o == k];  d out_o / d A_ok = m c_k;  d out_o / d b_o = m.
  // The colour's gradient, pixel by pixel, on all threads: each pixel adds o = 0, 1, 2 in turn to
  // each of its three channels, in one pass over the planes (nine passes before, the same sums).
  const int64_t count = static_cast<int64_t>(n);
  const T *g0 = d_out.plane(0), *g1 = d_out.plane(1), *g2 = d_out.plane(2);
  T *dc0 = d_in->plane(0), *dc1 = d_in->plane(1), *dc2 = d_in->plane(2);
  T a[9];
  for (int j = 0; j < 9; ++j) a[j] = static_cast<T>(p[j]);
  // Two loops, so neither loads the mask under a condition.
  if (m != nullptr) {
#pragma omp parallel for simd schedule(static) if (count >= kParallelPixels)
    for (int64_t i = 0; i < count; ++i)
      ColorTransformPixelBackward(a, g0, g1, g2, m[i], i, dc0, dc1, dc2);
  } else {
#pragma omp parallel for simd schedule(static) if (count >= kParallelPixels)
    for (int64_t i = 0; i < count; ++i)
      ColorTransformPixelBackward(a, g0, g1, g2, T(1), i, dc0, dc1, dc2);
  }
  // The twelve parameter sums: each a serial reduction whose order fixes its bits, so they run
  // side by side on the threads rather than split (on one thread they were ~1% of a training run,
  // the other thread waiting).
  const T* g[3] = {g0, g1, g2};
  double sums[3][4];
#pragma omp parallel for schedule(dynamic, 1) if (count >= kParallelPixels)
  for (int j = 0; j < 12; ++j) {
    const int o = j / 4, k = j % 4;
    sums[o][k] = k < 3 ? WeightedDot(g[o], m, in.plane(k), n) : WeightedSum(g[o], m, n);
  }
  for (int o = 0; o < 3; ++o) {
    for (int k = 0; k < 3; ++k) dp[3 * o + k] = sums[o][k];
    dp[9 + o] = sums[o][3];
  }
  for (int i = 0; i < kColorTransformSize; ++i) (*d_params)[i] += dp[i];
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
