#include "mgsr/render/rasterize_gaussians.h"

#include <omp.h>

#include <algorithm>
#include <cmath>

namespace mgsr {
namespace {

// Gathered per-tile fields (structure of arrays over the tile's Gaussians).
enum Field { kMx, kMy, kRad, kCa, kCb, kCc, kOp, kRefOp, kBeta, kZ, kCt0, kCt1, kCt2, kCr0, kCr1, kCr2, kNumFields };
// Gradient fields, per Gaussian.
enum GradField { gMx, gMy, gCa, gCb, gCc, gOp, gRefOp, gBeta, gZ, gCt0, gCt1, gCt2, gCr0, gCr1, gCr2, kGradStride };

void GatherTile(const ProjectedGaussians& p, const uint32_t* ids, int n, std::vector<float>* buffer) {
  buffer->resize(static_cast<size_t>(kNumFields) * n);
  float* f = buffer->data();
  for (int j = 0; j < n; ++j) {
    const uint32_t g = ids[j];
    f[kMx * n + j] = p.mean2d[2 * g];
    f[kMy * n + j] = p.mean2d[2 * g + 1];
    f[kRad * n + j] = p.radius[g];
    f[kCa * n + j] = p.conic[3 * g];
    f[kCb * n + j] = p.conic[3 * g + 1];
    f[kCc * n + j] = p.conic[3 * g + 2];
    f[kOp * n + j] = p.opacity[g];
    f[kRefOp * n + j] = p.ref_opacity[g];
    f[kBeta * n + j] = p.beta[g];
    f[kZ * n + j] = p.depth[g];
    for (int c = 0; c < 3; ++c) {
      f[(kCt0 + c) * n + j] = p.color_t[3 * g + c];
      f[(kCr0 + c) * n + j] = p.color_r[3 * g + c];
    }
  }
}

void EnsureScratch(RasterScratch* s, int threads) {
  if (static_cast<int>(s->tile_data.size()) < threads) {
    s->tile_data.resize(threads);
    s->tile_grad.resize(threads);
    s->grads.resize(threads);
  }
}

}  // namespace

void RasterizeGaussians(const ProjectedGaussians& p, const TileBins& bins, const GaussianRenderOptions& o,
                        GaussianRender* out, RasterScratch* scratch) {
  const int W = o.camera.width, H = o.camera.height;
  const size_t npix = static_cast<size_t>(W) * H;
  for (Image* im : {&out->color, &out->tran, &out->ref}) {
    if (im->width() != W || im->height() != H || im->channels() != 3) *im = Image(W, H, 3);
  }
  for (Image* im : {&out->weight, &out->depth, &out->alpha}) {
    if (im->width() != W || im->height() != H || im->channels() != 1) *im = Image(W, H, 1);
  }
  out->final_t.resize(npix);
  out->final_tr.resize(npix);
  out->depth_sum.resize(npix);
  out->last_t.resize(npix);
  out->last_r.resize(npix);
  const int threads = omp_get_max_threads();
  EnsureScratch(scratch, threads);
  const bool refl = o.reflection;
  const float bg[3] = {o.background[0], o.background[1], o.background[2]};

#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int tile = 0; tile < bins.num_tiles(); ++tile) {
    const int tx = tile % bins.tiles_x, ty = tile / bins.tiles_x;
    const uint32_t begin = bins.tile_start[tile];
    const int n = static_cast<int>(bins.tile_start[tile + 1] - begin);
    std::vector<float>& buffer = scratch->tile_data[omp_get_thread_num()];
    GatherTile(p, bins.ids.data() + begin, n, &buffer);
    const float* f = buffer.data();
    const float *mx = f + kMx * n, *my = f + kMy * n, *rad = f + kRad * n, *ca = f + kCa * n,
                *cb = f + kCb * n, *cc = f + kCc * n, *op = f + kOp * n, *rop = f + kRefOp * n,
                *beta = f + kBeta * n, *zz = f + kZ * n;
    const float* ct[3] = {f + kCt0 * n, f + kCt1 * n, f + kCt2 * n};
    const float* cr[3] = {f + kCr0 * n, f + kCr1 * n, f + kCr2 * n};
    const int x_end = std::min(W, (tx + 1) * kTileSize), y_end = std::min(H, (ty + 1) * kTileSize);
    for (int y = ty * kTileSize; y < y_end; ++y) {
      for (int x = tx * kTileSize; x < x_end; ++x) {
        const float px = x + 0.5f, py = y + 0.5f;
        float T = 1.0f, Tr = 1.0f;
        float Ct[3] = {0, 0, 0}, Cr[3] = {0, 0, 0};
        float Wsum = 0, Dsum = 0;
        bool done_t = false, done_r = !refl;
        uint32_t last_t = 0, last_r = 0;
        for (int j = 0; j < n && !(done_t && done_r); ++j) {
          const float dx = px - mx[j], dy = py - my[j];
          if (std::abs(dx) > rad[j] || std::abs(dy) > rad[j]) continue;
          const float power = -0.5f * (ca[j] * dx * dx + cc[j] * dy * dy) - cb[j] * dx * dy;
          if (power > 0.0f) continue;
          const float G = std::exp(power);
          if (!done_t) {
            const float a = std::min(kMaxAlpha, op[j] * G);
            if (a >= kMinAlpha) {
              const float test = T * (1.0f - a);
              if (test < kMinTransmittance) {
                done_t = true;
              } else {
                const float w = a * T;
                for (int c = 0; c < 3; ++c) Ct[c] += w * ct[c][j];
                Wsum += w * beta[j];
                Dsum += w * zz[j];
                T = test;
                last_t = j + 1;
              }
            }
          }
          if (!done_r) {
            const float a = std::min(kMaxAlpha, rop[j] * G);
            if (a >= kMinAlpha) {
              const float test = Tr * (1.0f - a);
              if (test < kMinTransmittance) {
                done_r = true;
              } else {
                const float w = a * Tr;
                for (int c = 0; c < 3; ++c) Cr[c] += w * cr[c][j];
                Tr = test;
                last_r = j + 1;
              }
            }
          }
        }
        const size_t pix = static_cast<size_t>(y) * W + x;
        const float A = 1.0f - T;
        for (int c = 0; c < 3; ++c) {
          const float tran = Ct[c] + T * bg[c];
          out->tran.plane(c)[pix] = tran;
          out->ref.plane(c)[pix] = Cr[c];
          out->color.plane(c)[pix] = tran + Wsum * Cr[c];
        }
        out->weight.plane(0)[pix] = Wsum;
        out->alpha.plane(0)[pix] = A;
        out->depth.plane(0)[pix] = A >= kMinDepthAlpha ? Dsum / A : 0.0f;
        out->final_t[pix] = T;
        out->final_tr[pix] = Tr;
        out->depth_sum[pix] = Dsum;
        out->last_t[pix] = last_t;
        out->last_r[pix] = last_r;
      }
    }
  }
}

void RasterizeGaussiansBackward(const ProjectedGaussians& p, const TileBins& bins, const GaussianRenderOptions& o,
                                const GaussianRender& r, const GaussianRenderGrad& g,
                                ProjectedGaussiansGrad* d, RasterScratch* scratch) {
  const int W = o.camera.width, H = o.camera.height;
  const size_t num = p.size();
  const int threads = omp_get_max_threads();
  EnsureScratch(scratch, threads);
  const bool refl = o.reflection;
  const float bg[3] = {o.background[0], o.background[1], o.background[2]};

#pragma omp parallel num_threads(threads)
  {
    const int thread = omp_get_thread_num();
    std::vector<float>& acc = scratch->grads[thread];
    acc.assign(num * kGradStride, 0.0f);
#pragma omp for schedule(dynamic, 1)
    for (int tile = 0; tile < bins.num_tiles(); ++tile) {
      const int tx = tile % bins.tiles_x, ty = tile / bins.tiles_x;
      const uint32_t begin = bins.tile_start[tile];
      const int n = static_cast<int>(bins.tile_start[tile + 1] - begin);
      if (n == 0) continue;
      std::vector<float>& buffer = scratch->tile_data[thread];
      GatherTile(p, bins.ids.data() + begin, n, &buffer);
      std::vector<float>& tg = scratch->tile_grad[thread];
      tg.assign(static_cast<size_t>(n) * kGradStride, 0.0f);
      const float* f = buffer.data();
      const float *mx = f + kMx * n, *my = f + kMy * n, *rad = f + kRad * n, *ca = f + kCa * n,
                  *cb = f + kCb * n, *cc = f + kCc * n, *op = f + kOp * n, *rop = f + kRefOp * n,
                  *beta = f + kBeta * n, *zz = f + kZ * n;
      const float* ct[3] = {f + kCt0 * n, f + kCt1 * n, f + kCt2 * n};
      const float* cr[3] = {f + kCr0 * n, f + kCr1 * n, f + kCr2 * n};
      const int x_end = std::min(W, (tx + 1) * kTileSize), y_end = std::min(H, (ty + 1) * kTileSize);
      for (int y = ty * kTileSize; y < y_end; ++y) {
        for (int x = tx * kTileSize; x < x_end; ++x) {
          const size_t pix = static_cast<size_t>(y) * W + x;
          // Upstream gradients, folded onto the chains: C = C_tran + W C_ref, D = Dsum / A.
          float gt[3], gr[3], gW = 0, gN = 0, gA = 0;
          const float Wv = r.weight.plane(0)[pix];
          for (int c = 0; c < 3; ++c) {
            const float gc = g.color.empty() ? 0.0f : g.color.plane(c)[pix];
            gt[c] = gc + (g.tran.empty() ? 0.0f : g.tran.plane(c)[pix]);
            gr[c] = Wv * gc + (g.ref.empty() ? 0.0f : g.ref.plane(c)[pix]);
            gW += gc * r.ref.plane(c)[pix];
          }
          if (!g.weight.empty()) gW += g.weight.plane(0)[pix];
          if (!g.alpha.empty()) gA += g.alpha.plane(0)[pix];
          const float A = 1.0f - r.final_t[pix];
          if (!g.depth.empty() && A >= kMinDepthAlpha) {
            const float gD = g.depth.plane(0)[pix];
            gN = gD / A;
            gA -= gD * r.depth_sum[pix] / (A * A);
          }
          const float T_final = r.final_t[pix];
          const float bg_dot = bg[0] * gt[0] + bg[1] * gt[1] + bg[2] * gt[2];
          const uint32_t last_t = r.last_t[pix], last_r = refl ? r.last_r[pix] : 0;
          float T = T_final, Tr = r.final_tr[pix];
          float St[3] = {0, 0, 0}, Sr[3] = {0, 0, 0}, Sbeta = 0, Sz = 0;  // "behind" accumulators
          const float px = x + 0.5f, py = y + 0.5f;
          for (int j = static_cast<int>(std::max(last_t, last_r)) - 1; j >= 0; --j) {
            const float dx = px - mx[j], dy = py - my[j];
            if (std::abs(dx) > rad[j] || std::abs(dy) > rad[j]) continue;
            const float power = -0.5f * (ca[j] * dx * dx + cc[j] * dy * dy) - cb[j] * dx * dy;
            if (power > 0.0f) continue;
            const float G = std::exp(power);
            float* gj = tg.data() + static_cast<size_t>(j) * kGradStride;
            float dG = 0;
            if (j < static_cast<int>(last_t)) {
              const float raw = op[j] * G;
              const float a = std::min(kMaxAlpha, raw);
              if (a >= kMinAlpha) {
                T /= (1.0f - a);
                const float w = a * T;
                float da = 0;
                for (int c = 0; c < 3; ++c) {
                  gj[gCt0 + c] += w * gt[c];
                  da += (ct[c][j] - St[c]) * gt[c];
                  St[c] = a * ct[c][j] + (1.0f - a) * St[c];
                }
                gj[gBeta] += w * gW;
                gj[gZ] += w * gN;
                da += (beta[j] - Sbeta) * gW + (zz[j] - Sz) * gN;
                da *= T;
                da += (T_final / (1.0f - a)) * (gA - bg_dot);
                Sbeta = a * beta[j] + (1.0f - a) * Sbeta;
                Sz = a * zz[j] + (1.0f - a) * Sz;
                if (raw < kMaxAlpha) {  // the clamp at 0.99 has zero slope
                  gj[gOp] += G * da;
                  dG += op[j] * da;
                }
              }
            }
            if (j < static_cast<int>(last_r)) {
              const float raw = rop[j] * G;
              const float a = std::min(kMaxAlpha, raw);
              if (a >= kMinAlpha) {
                Tr /= (1.0f - a);
                const float w = a * Tr;
                float da = 0;
                for (int c = 0; c < 3; ++c) {
                  gj[gCr0 + c] += w * gr[c];
                  da += (cr[c][j] - Sr[c]) * gr[c];
                  Sr[c] = a * cr[c][j] + (1.0f - a) * Sr[c];
                }
                da *= Tr;
                if (raw < kMaxAlpha) {
                  gj[gRefOp] += G * da;
                  dG += rop[j] * da;
                }
              }
            }
            const float dpower = G * dG;
            gj[gMx] += dpower * (ca[j] * dx + cb[j] * dy);
            gj[gMy] += dpower * (cb[j] * dx + cc[j] * dy);
            gj[gCa] += -0.5f * dpower * dx * dx;
            gj[gCb] += -dpower * dx * dy;
            gj[gCc] += -0.5f * dpower * dy * dy;
          }
        }
      }
      // Scatter this tile's gradients to the thread's per-Gaussian accumulators.
      const uint32_t* ids = bins.ids.data() + begin;
      for (int j = 0; j < n; ++j) {
        float* dst = acc.data() + static_cast<size_t>(ids[j]) * kGradStride;
        const float* src = tg.data() + static_cast<size_t>(j) * kGradStride;
        for (int k = 0; k < kGradStride; ++k) dst[k] += src[k];
      }
    }
  }
  // Reduce the per-thread accumulators into the projected-quantity gradients.
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < static_cast<int64_t>(num); ++i) {
    float s[kGradStride] = {};
    for (int t = 0; t < threads; ++t) {
      const float* src = scratch->grads[t].data() + static_cast<size_t>(i) * kGradStride;
      for (int k = 0; k < kGradStride; ++k) s[k] += src[k];
    }
    d->mean2d[2 * i] += s[gMx];
    d->mean2d[2 * i + 1] += s[gMy];
    d->conic[3 * i] += s[gCa];
    d->conic[3 * i + 1] += s[gCb];
    d->conic[3 * i + 2] += s[gCc];
    d->opacity[i] += s[gOp];
    d->ref_opacity[i] += s[gRefOp];
    d->beta[i] += s[gBeta];
    d->depth[i] += s[gZ];
    for (int c = 0; c < 3; ++c) {
      d->color_t[3 * i + c] += s[gCt0 + c];
      d->color_r[3 * i + c] += s[gCr0 + c];
    }
  }
}

}  // namespace mgsr
