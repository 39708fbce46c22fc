#include "mgsr/eval/image_metrics.h"

#include <cmath>
#include <limits>

#include <glog/logging.h>

namespace mgsr {

std::vector<float> SsimWindow() {
  constexpr int kSize = 11;
  constexpr double kSigma = 1.5;
  std::vector<float> w(kSize);
  double sum = 0;
  for (int i = 0; i < kSize; ++i) {
    const double x = i - kSize / 2;
    sum += std::exp(-x * x / (2 * kSigma * kSigma));
  }
  for (int i = 0; i < kSize; ++i) {
    const double x = i - kSize / 2;
    w[i] = static_cast<float>(std::exp(-x * x / (2 * kSigma * kSigma)) / sum);
  }
  return w;
}

void BlurZeroPadded(const float* in, int width, int height, const std::vector<float>& kernel,
                    float* out, std::vector<float>* scratch) {
  const int r = static_cast<int>(kernel.size()) / 2;
  scratch->resize(static_cast<size_t>(width) * height);
  float* tmp = scratch->data();
  // Horizontal pass.
  for (int y = 0; y < height; ++y) {
    const float* row = in + static_cast<size_t>(y) * width;
    float* dst = tmp + static_cast<size_t>(y) * width;
    for (int x = 0; x < width; ++x) {
      const int k0 = std::max(0, r - x), k1 = std::min(2 * r, width - 1 - x + r);
      float acc = 0;
      for (int k = k0; k <= k1; ++k) acc += kernel[k] * row[x + k - r];
      dst[x] = acc;
    }
  }
  // Vertical pass, row by row so the inner loop runs over contiguous x (vectorises).
  for (int y = 0; y < height; ++y) {
    float* dst = out + static_cast<size_t>(y) * width;
    for (int x = 0; x < width; ++x) dst[x] = 0;
    const int k0 = std::max(0, r - y), k1 = std::min(2 * r, height - 1 - y + r);
    for (int k = k0; k <= k1; ++k) {
      const float w = kernel[k];
      const float* src = tmp + static_cast<size_t>(y + k - r) * width;
      for (int x = 0; x < width; ++x) dst[x] += w * src[x];
    }
  }
}

double Psnr(const Image& a, const Image& b) {
  CHECK(a.SameShape(b)) << "PSNR of images with different shapes";
  double se = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    const double d = static_cast<double>(a.data()[i]) - b.data()[i];
    se += d * d;
  }
  const double mse = se / std::max<size_t>(1, a.size());
  if (mse <= 0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(1.0 / mse);
}

double Ssim(const Image& a, const Image& b) {
  CHECK(a.SameShape(b)) << "SSIM of images with different shapes";
  constexpr double kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;
  const int w = a.width(), h = a.height();
  const size_t n = a.plane_size();
  const std::vector<float> window = SsimWindow();
  std::vector<float> scratch, prod(n), mu_a(n), mu_b(n), saa(n), sbb(n), sab(n);
  double total = 0;
  for (int c = 0; c < a.channels(); ++c) {
    const float* pa = a.plane(c);
    const float* pb = b.plane(c);
    BlurZeroPadded(pa, w, h, window, mu_a.data(), &scratch);
    BlurZeroPadded(pb, w, h, window, mu_b.data(), &scratch);
    for (size_t i = 0; i < n; ++i) prod[i] = pa[i] * pa[i];
    BlurZeroPadded(prod.data(), w, h, window, saa.data(), &scratch);
    for (size_t i = 0; i < n; ++i) prod[i] = pb[i] * pb[i];
    BlurZeroPadded(prod.data(), w, h, window, sbb.data(), &scratch);
    for (size_t i = 0; i < n; ++i) prod[i] = pa[i] * pb[i];
    BlurZeroPadded(prod.data(), w, h, window, sab.data(), &scratch);
    for (size_t i = 0; i < n; ++i) {
      const double ma = mu_a[i], mb = mu_b[i];
      const double va = saa[i] - ma * ma, vb = sbb[i] - mb * mb, cov = sab[i] - ma * mb;
      total += ((2 * ma * mb + kC1) * (2 * cov + kC2)) / ((ma * ma + mb * mb + kC1) * (va + vb + kC2));
    }
  }
  return total / std::max<size_t>(1, a.size());
}

}  // namespace mgsr
