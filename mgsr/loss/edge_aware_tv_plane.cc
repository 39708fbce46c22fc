#include "mgsr/loss/edge_aware_tv_plane.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "mgsr/loss/parallel_pixels.h"
#include "mgsr/render/simd16.h"

namespace mgsr {
namespace {

// a[i] = exp(a[i]) for a[i] <= 0.
inline void ExpInPlace(float* a, int n) {
  using simd::F16;
  int i = 0;
  for (; i + 16 <= n; i += 16) {
    simd::Store(a + i, simd::Exp(simd::Max(simd::Load<F16>(a + i), simd::Splat<F16>(-87.0f))));
  }
  if (i < n) {
    float tail[16] = {};
    std::copy(a + i, a + n, tail);
    const F16 e = simd::Exp(simd::Max(simd::Load<F16>(tail), simd::Splat<F16>(-87.0f)));
    simd::Store(tail, e);
    std::copy(tail, tail + (n - i), a + i);
  }
}
inline void ExpInPlace(double* a, int n) {
  for (int i = 0; i < n; ++i) a[i] = std::exp(a[i]);
}

template <typename T>
void SumsT(const T* P, int channels, const T* I, int guide_channels, const T* gamma, int w, int h,
           T scale_v, T scale_h, T* grad, double* vertical, double* horizontal) {
  const size_t n = static_cast<size_t>(w) * h;
  static thread_local std::vector<T> weights;
  static thread_local std::vector<double> row_sums;
  weights.resize(2 * n);
  row_sums.resize(2 * static_cast<size_t>(h));
  // Pointers, not the thread_local vectors, go into the parallel region.
  T* const wv = weights.data();  // row y: between rows y and y + 1 (0 on the last row)
  T* const wh = wv + n;          // column x: between columns x and x + 1 (0 on the last column)
  double* const sums = row_sums.data();
  const T inv_guide = T(1) / static_cast<T>(guide_channels);
  // d (w d^2) / d p = 2 w d (times -1 or +1 for the two pixels of the pair).
  const T gv = 2 * scale_v, gh = 2 * scale_h;

#pragma omp parallel if (static_cast <int64_t>(w) * h >= kParallelPixels)
  {
    // 1. Edge weights from the guide.
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y) {
      const size_t o = static_cast<size_t>(y) * w;
      T* v = wv + o;
      T* hr = wh + o;
      std::fill(v, v + w, T(0));
      std::fill(hr, hr + w, T(0));
      for (int c = 0; c < guide_channels; ++c) {
        const T* row = I + c * n + o;
        if (y + 1 < h) {
          const T* below = row + w;
#pragma omp simd
          for (int x = 0; x < w; ++x) v[x] -= std::abs(below[x] - row[x]);
        }
#pragma omp simd
        for (int x = 0; x < w - 1; ++x) hr[x] -= std::abs(row[x + 1] - row[x]);
      }
      for (int x = 0; x < w; ++x) {
        v[x] *= inv_guide;
        hr[x] *= inv_guide;
      }
      ExpInPlace(v, w);
      ExpInPlace(hr, w);
      if (y + 1 == h) std::fill(v, v + w, T(0));
      hr[w - 1] = 0;
      if (gamma != nullptr) {
        const T* g = gamma + o;
        if (y + 1 < h) {
#pragma omp simd
          for (int x = 0; x < w; ++x) v[x] *= g[x] * g[x + w];
        }
#pragma omp simd
        for (int x = 0; x < w - 1; ++x) hr[x] *= g[x] * g[x + 1];
      }
    }

    // 2. Sums and the gradient, row by row: pixel (y, x) gathers -2 w d from its own differences
    // and +2 w d from those of (y - 1, x) and (y, x - 1).
#pragma omp for schedule(static)
    for (int y = 0; y < h; ++y) {
      const size_t o = static_cast<size_t>(y) * w;
      const T* v = wv + o;
      const T* hr = wh + o;
      double sv = 0, sh = 0;
      for (int c = 0; c < channels; ++c) {
        const T* p = P + c * n + o;
        const T* below = y + 1 < h ? p + w : p;  // the last row's weights are 0
#pragma omp simd reduction(+ : sv)
        for (int x = 0; x < w; ++x) {
          const T d = below[x] - p[x];
          sv += v[x] * d * d;
        }
#pragma omp simd reduction(+ : sh)
        for (int x = 0; x < w - 1; ++x) {
          const T d = p[x + 1] - p[x];
          sh += hr[x] * d * d;
        }
        if (grad == nullptr) continue;
        T* g = grad + c * n + o;
        const T* above = y > 0 ? p - w : p;
        const T* v_above = y > 0 ? v - w : v;
        const T up = y > 0 ? T(1) : T(0);
#pragma omp simd
        for (int x = 0; x < w; ++x) {
          g[x] += gv * (up * v_above[x] * (p[x] - above[x]) - v[x] * (below[x] - p[x]));
        }
        g[0] -= gh * hr[0] * (w > 1 ? p[1] - p[0] : T(0));
#pragma omp simd
        for (int x = 1; x < w; ++x) {
          const T right = x + 1 < w ? p[x + 1] : p[x];  // the last column's weight is 0
          g[x] += gh * (hr[x - 1] * (p[x] - p[x - 1]) - hr[x] * (right - p[x]));
        }
      }
      sums[2 * y] = sv;
      sums[2 * y + 1] = sh;
    }
  }
  double tv = 0, th = 0;
  for (int y = 0; y < h; ++y) {
    tv += sums[2 * y];
    th += sums[2 * y + 1];
  }
  *vertical = tv;
  *horizontal = th;
}

}  // namespace

void EdgeAwareTvSums(const float* P, int channels, const float* I, int guide_channels,
                     const float* gamma, int width, int height, float scale_v, float scale_h,
                     float* grad, double* vertical, double* horizontal) {
  SumsT(P, channels, I, guide_channels, gamma, width, height, scale_v, scale_h, grad, vertical,
        horizontal);
}

void EdgeAwareTvSums(const double* P, int channels, const double* I, int guide_channels,
                     const double* gamma, int width, int height, double scale_v, double scale_h,
                     double* grad, double* vertical, double* horizontal) {
  SumsT(P, channels, I, guide_channels, gamma, width, height, scale_v, scale_h, grad, vertical,
        horizontal);
}

}  // namespace mgsr
