#include "mgsr/loss/dssim_plane.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

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

// A ring of kTaps rows per plane: row q of the image lives in slot q mod kTaps.
template <typename T>
struct RowRing {
  T* base = nullptr;
  int width = 0;
  T* Row(int plane, int q) const {
    return base + (static_cast<size_t>(plane) * kTaps + q % kTaps) * width;
  }
  // The kTaps rows of `plane` around row r (the zero row beyond the image).
  void Around(int plane, int r, int height, const T* zeros, const T** rows) const {
    for (int k = 0; k < kTaps; ++k) {
      const int rr = r + k - kRadius;
      rows[k] = rr >= 0 && rr < height ? Row(plane, rr) : zeros;
    }
  }
};

template <typename T>
double SsimPlaneSumT(const T* x, const T* y, int width, int height, T scale, T* grad) {
  const T* w = WindowFor<T>().w;
  const size_t padded = static_cast<size_t>(width) + 2 * kRadius;
  // resize() keeps the capacity: after the first call of a size, nothing is allocated.
  static thread_local std::vector<double> row_sums;
  row_sums.resize(height);
  // A pointer, not the thread_local vector, goes into the parallel region: a worker thread
  // naming `row_sums` would get its own (empty) one.
  double* sums = row_sums.data();
  const T C1 = T(0.01 * 0.01), C2 = T(0.03 * 0.03);

  // Threaded from a 128 px view on (it was from 256 px), as the other loss kernels.
#pragma omp parallel if (static_cast <int64_t>(width) * height >= kParallelPixels)
  {
    // Per worker: padded input rows (x, y, x^2, y^2, xy, then a1, a2, a3), the vertically blurred
    // rows (five moments, then three partials), a row of zeros, and two rings of kTaps rows: the
    // horizontal blurs of the five moments and of the three partials. A worker walks a band of
    // rows; each row of the rings is made once and used by the kTaps rows around it while it is in
    // cache (at photo size the eight blurred planes had gone through memory).
    static thread_local std::vector<T> rows;
    rows.resize((kMoments + kPartials) * (padded + width) + width +
                (kMoments + kPartials) * kTaps * static_cast<size_t>(width));
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
    const RowRing<T> moments{zeros + width, width};
    const RowRing<T> partials{zeros + width + static_cast<size_t>(kMoments) * kTaps * width, width};
    const T* around[kTaps];

    // The worker's band of rows [r0, r1): an equal share, so that halos are few.
#ifdef _OPENMP
    const int workers = omp_get_num_threads(), me = omp_get_thread_num();
#else
    const int workers = 1, me = 0;
#endif
    const int r0 = static_cast<int>(static_cast<int64_t>(height) * me / workers);
    const int r1 = static_cast<int>(static_cast<int64_t>(height) * (me + 1) / workers);
    // Rows of the SSIM map the band needs: its own, and for the gradient kRadius either side.
    const int halo = grad != nullptr ? kRadius : 0;
    const int p_begin = std::max(0, r0 - halo), p_end = std::min(height, r1 + halo);

    // Row q of the moments' horizontal blurs is made at step q; the SSIM row p = q - kRadius
    // (which reads moment rows up to q) at the same step; the gradient row t = p - kRadius (which
    // reads partial rows up to p) too.
    for (int q = p_begin - kRadius; r0 < r1 && q < r1 + 2 * kRadius; ++q) {
      // 1. Horizontal blurs of the five moments of row q, from one read of the row.
      if (q >= std::max(0, p_begin - kRadius) && q < std::min(height, p_end + kRadius)) {
        const T* xr = x + static_cast<size_t>(q) * width;
        const T* yr = y + static_cast<size_t>(q) * width;
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
        for (int m = 0; m < kMoments; ++m) BlurRow(pad[m], width, w, moments.Row(m, q));
      }

      // 2. Row p: vertical blurs, the SSIM map and its partials in (mu_x, E[x^2], E[xy]) (the
      // others held fixed), and the horizontal blur of the partials.
      const int p = q - kRadius;
      if (p >= p_begin && p < p_end) {
        for (int m = 0; m < kMoments; ++m) {
          moments.Around(m, p, height, zeros, around);
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
        if (p >= r0 && p < r1) sums[p] = sum;  // halo rows belong to the neighbouring band
        if (grad != nullptr) {
          for (int m = 0; m < kPartials; ++m)
            BlurRow(pad[kMoments + m], width, w, partials.Row(m, p));
        }
      }

      // 3. Gradient row t: the zero-padded symmetric blur is its own adjoint, so
      // d/dx = G*a1 + 2x G*a2 + y G*a3.
      const int t = p - kRadius;
      if (grad != nullptr && t >= r0 && t < r1) {
        for (int m = 0; m < kPartials; ++m) {
          partials.Around(m, t, height, zeros, around);
          BlurColumn(around, width, w, vert[kMoments + m]);
        }
        const size_t o = static_cast<size_t>(t) * width;
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
