#include "mgsr/eval/image_metrics.h"

#include <glog/logging.h>

#include <cmath>
#include <limits>

#include "mgsr/core/separable_blur.h"

namespace mgsr {

std::vector<float> SsimWindow() { return SsimWindowT<float>(); }

void BlurZeroPadded(const float* in, int width, int height, const std::vector<float>& kernel,
                    float* out, std::vector<float>* scratch) {
  BlurZeroPaddedT(in, width, height, kernel, out, scratch);
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

double ForegroundPsnr(const Image& a, const Image& b, const Image& mask) {
  CHECK(a.SameShape(b)) << "PSNR of images with different shapes";
  CHECK(mask.width() == a.width() && mask.height() == a.height()) << "mask of another size";
  double se = 0;
  size_t n = 0;
  for (size_t i = 0; i < a.plane_size(); ++i) {
    if (!(mask.data()[i] >= 0.5f)) continue;
    for (int c = 0; c < a.channels(); ++c) {
      const double d = static_cast<double>(a.plane(c)[i]) - b.plane(c)[i];
      se += d * d;
      ++n;
    }
  }
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  const double mse = se / n;
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
      total +=
          ((2 * ma * mb + kC1) * (2 * cov + kC2)) / ((ma * ma + mb * mb + kC1) * (va + vb + kC2));
    }
  }
  return total / std::max<size_t>(1, a.size());
}

}  // namespace mgsr
