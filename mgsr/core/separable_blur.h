// Separable blur with zero padding (the convolution SSIM uses), for any scalar type. A symmetric
// kernel with zero padding is its own adjoint, which the SSIM backward relies on.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace mgsr {

// The normalised 1-D Gaussian window of SSIM: 11 taps, sigma 1.5.
template <typename T>
std::vector<T> SsimWindowT() {
  constexpr int kSize = 11;
  constexpr double kSigma = 1.5;
  std::vector<T> w(kSize);
  double sum = 0;
  for (int i = 0; i < kSize; ++i)
    sum += std::exp(-(i - kSize / 2) * (i - kSize / 2) / (2 * kSigma * kSigma));
  for (int i = 0; i < kSize; ++i) {
    w[i] =
        static_cast<T>(std::exp(-(i - kSize / 2) * (i - kSize / 2) / (2 * kSigma * kSigma)) / sum);
  }
  return w;
}

template <typename T>
void BlurZeroPaddedT(const T* in, int width, int height, const std::vector<T>& kernel, T* out,
                     std::vector<T>* scratch) {
  const int r = static_cast<int>(kernel.size()) / 2;
  scratch->resize(static_cast<size_t>(width) * height);
  T* tmp = scratch->data();
  const int taps = static_cast<int>(kernel.size());
  // Both passes loop over taps outside and pixels inside, so the inner loops run over contiguous
  // memory and vectorise; rows are independent and split across threads for large images.
#pragma omp parallel for schedule(static) if (static_cast <int64_t>(width) * height >= 65536)
  for (int y = 0; y < height; ++y) {
    const T* row = in + static_cast<size_t>(y) * width;
    T* dst = tmp + static_cast<size_t>(y) * width;
    std::fill(dst, dst + width, T(0));
    for (int k = 0; k < taps; ++k) {
      const T w = kernel[k];
      const int shift = k - r;  // dst[x] += w * row[x + shift] for 0 <= x + shift < width
      const int x0 = std::max(0, -shift), x1 = std::min(width, width - shift);
      for (int x = x0; x < x1; ++x) dst[x] += w * row[x + shift];
    }
  }
#pragma omp parallel for schedule(static) if (static_cast <int64_t>(width) * height >= 65536)
  for (int y = 0; y < height; ++y) {
    T* dst = out + static_cast<size_t>(y) * width;
    std::fill(dst, dst + width, T(0));
    const int k0 = std::max(0, r - y), k1 = std::min(2 * r, height - 1 - y + r);
    for (int k = k0; k <= k1; ++k) {
      const T w = kernel[k];
      const T* src = tmp + static_cast<size_t>(y + k - r) * width;
      for (int x = 0; x < width; ++x) dst[x] += w * src[x];
    }
  }
}

}  // namespace mgsr
