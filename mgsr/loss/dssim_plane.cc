#include "mgsr/loss/dssim_plane.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "mgsr/core/separable_blur.h"
#include "mgsr/loss/parallel_pixels.h"

namespace mgsr {
namespace {

constexpr int kTaps = 11, kRadius = kTaps / 2;
// Planes of the per-call scratch: the horizontal blurs of x, y, x^2, y^2, xy (the five moments)
// and of the three partials of the SSIM map (a1, a2, a3 below).
constexpr int kMoments = 5, kPartials = 3;

template <typename T>
struct Window {
  T w[kTaps];
  Window() {
    const std::vector<T> v = SsimWindowT<T>();
    std::copy(v.begin(), v.end(), w);
  }
};

template <typename T>
const Window<T>& WindowFor() {
  static const Window<T> window;
  return window;
}

// out[x] = sum_k w[k] in[x + k - kRadius] with zeros outside the row: `padded` holds the row at
// [kRadius, kRadius + width) and kRadius zeros on either side. Vectorised over x.
template <typename T>
inline void BlurRow(const T* __restrict padded, int width, const T* __restrict w,
                    T* __restrict out) {
#pragma omp simd
  for (int x = 0; x < width; ++x) {
    T s = 0;
    for (int k = 0; k < kTaps; ++k) s += w[k] * padded[x + k];
    out[x] = s;
  }
}

// out[x] = sum_k w[k] rows[k][x]: the vertical blur of one row, rows outside the image pointing
// at a row of zeros.
template <typename T>
inline void BlurColumn(const T* const* rows, int width, const T* __restrict w, T* __restrict out) {
  const T *r0 = rows[0], *r1 = rows[1], *r2 = rows[2], *r3 = rows[3], *r4 = rows[4], *r5 = rows[5],
          *r6 = rows[6], *r7 = rows[7], *r8 = rows[8], *r9 = rows[9], *r10 = rows[10];
#pragma omp simd
  for (int x = 0; x < width; ++x) {
    out[x] = w[0] * r0[x] + w[1] * r1[x] + w[2] * r2[x] + w[3] * r3[x] + w[4] * r4[x] +
             w[5] * r5[x] + w[6] * r6[x] + w[7] * r7[x] + w[8] * r8[x] + w[9] * r9[x] +
             w[10] * r10[x];
  }
}

// The kTaps rows of `plane` around row r (zeros beyond the image).
template <typename T>
inline void RowsAround(const T* plane, int width, int height, int r, const T* zeros,
                       const T** rows) {
  for (int k = 0; k < kTaps; ++k) {
    const int rr = r + k - kRadius;
    rows[k] = rr >= 0 && rr < height ? plane + static_cast<size_t>(rr) * width : zeros;
  }
}

template <typename T>
double SsimPlaneSumT(const T* x, const T* y, int width, int height, T scale, T* grad) {
  const T* w = WindowFor<T>().w;
  const size_t n = static_cast<size_t>(width) * height;
  const size_t padded = static_cast<size_t>(width) + 2 * kRadius;
  // resize() keeps the capacity: after the first call of a size, nothing is allocated.
  static thread_local std::vector<T> planes;
  static thread_local std::vector<double> row_sums;
  planes.resize((kMoments + kPartials) * n);
  row_sums.resize(height);
  // Pointers, not the thread_local vectors, go into the parallel region: a worker thread naming
  // `planes` would get its own (empty) one.
  T* blurred[kMoments + kPartials];
  for (int m = 0; m < kMoments + kPartials; ++m) blurred[m] = planes.data() + m * n;
  double* sums = row_sums.data();
  const T C1 = T(0.01 * 0.01), C2 = T(0.03 * 0.03);

  // Threaded from a 128 px view on (it was from 256 px), as the other loss kernels.
#pragma omp parallel if (static_cast <int64_t>(width) * height >= kParallelPixels)
  {
    // Per worker: padded input rows (x, y, x^2, y^2, xy, then a1, a2, a3), the vertically blurred
    // rows (five moments, then three partials) and a row of zeros.
    static thread_local std::vector<T> rows;
    rows.resize((kMoments + kPartials) * (padded + width) + width);
    T* pad[kMoments + kPartials];
    T* vert[kMoments + kPartials];
    for (int m = 0; m < kMoments + kPartials; ++m) {
      pad[m] = rows.data() + m * padded;
      vert[m] = rows.data() + (kMoments + kPartials) * padded + m * width;
      std::fill(pad[m], pad[m] + kRadius, T(0));
      std::fill(pad[m] + kRadius + width, pad[m] + padded, T(0));
    }
    T* zeros = rows.data() + (kMoments + kPartials) * (padded + width);
    std::fill(zeros, zeros + width, T(0));
    const T* around[kTaps];

    // 1. Horizontal blurs of the five moments, from one read of each row.
#pragma omp for schedule(static)
    for (int r = 0; r < height; ++r) {
      const T* xr = x + static_cast<size_t>(r) * width;
      const T* yr = y + static_cast<size_t>(r) * width;
      T *px = pad[0] + kRadius, *py = pad[1] + kRadius, *pxx = pad[2] + kRadius,
        *pyy = pad[3] + kRadius, *pxy = pad[4] + kRadius;
      // Distinct rows of the worker's scratch and the inputs: GCC could not tell they do not
      // overlap and kept this loop scalar (a tenth of the kernel's time).
#pragma omp simd
      for (int i = 0; i < width; ++i) {
        px[i] = xr[i];
        py[i] = yr[i];
        pxx[i] = xr[i] * xr[i];
        pyy[i] = yr[i] * yr[i];
        pxy[i] = xr[i] * yr[i];
      }
      for (int m = 0; m < kMoments; ++m)
        BlurRow(pad[m], width, w, blurred[m] + static_cast<size_t>(r) * width);
    }

    // 2. Vertical blurs, the SSIM map and its partials in (mu_x, E[x^2], E[xy]) (the others held
    // fixed), and the horizontal blur of the partials, row by row.
#pragma omp for schedule(static)
    for (int r = 0; r < height; ++r) {
      for (int m = 0; m < kMoments; ++m) {
        RowsAround(blurred[m], width, height, r, zeros, around);
        BlurColumn(around, width, w, vert[m]);
      }
      const T *mx = vert[0], *my = vert[1], *exx = vert[2], *eyy = vert[3], *exy = vert[4];
      T *a1 = pad[5] + kRadius, *a2 = pad[6] + kRadius, *a3 = pad[7] + kRadius;
      double sum = 0;
#pragma omp simd reduction(+ : sum)
      for (int i = 0; i < width; ++i) {
        const T ux = mx[i], uy = my[i];
        const T vx = exx[i] - ux * ux, vy = eyy[i] - uy * uy, cxy = exy[i] - ux * uy;
        const T A = 2 * ux * uy + C1, B = 2 * cxy + C2, C = ux * ux + uy * uy + C1,
                D = vx + vy + C2;
        const T inv_cd = 1 / (C * D);
        const T S = A * B * inv_cd;
        sum += S;
        a1[i] = scale * (2 * uy * (B - A) * inv_cd - 2 * ux * S * (1 / C - 1 / D));
        a2[i] = scale * (-S / D);
        a3[i] = scale * (2 * A * inv_cd);
      }
      sums[r] = sum;
      if (grad != nullptr) {
        for (int m = kMoments; m < kMoments + kPartials; ++m)
          BlurRow(pad[m], width, w, blurred[m] + static_cast<size_t>(r) * width);
      }
    }

    // 3. The gradient: the zero-padded symmetric blur is its own adjoint, so
    // d/dx = G*a1 + 2x G*a2 + y G*a3.
    if (grad != nullptr) {
#pragma omp for schedule(static)
      for (int r = 0; r < height; ++r) {
        for (int m = kMoments; m < kMoments + kPartials; ++m) {
          RowsAround(blurred[m], width, height, r, zeros, around);
          BlurColumn(around, width, w, vert[m]);
        }
        const size_t o = static_cast<size_t>(r) * width;
        const T *b1 = vert[5], *b2 = vert[6], *b3 = vert[7];
        const T *xr = x + o, *yr = y + o;
        T* g = grad + o;
#pragma omp simd
        for (int i = 0; i < width; ++i) g[i] += b1[i] + 2 * xr[i] * b2[i] + yr[i] * b3[i];
      }
    }
  }
  double total = 0;
  for (int r = 0; r < height; ++r) total += sums[r];
  return total;
}

}  // namespace

double SsimPlaneSum(const float* x, const float* y, int width, int height, float scale,
                    float* grad) {
  return SsimPlaneSumT(x, y, width, height, scale, grad);
}

double SsimPlaneSum(const double* x, const double* y, int width, int height, double scale,
                    double* grad) {
  return SsimPlaneSumT(x, y, width, height, scale, grad);
}

}  // namespace mgsr
