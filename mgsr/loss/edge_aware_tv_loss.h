// Edge-aware total variation (reference 1.14, after GS-IR): for a buffer P (C x H x W) and a guide
// image I (3 channels),
//   TV = mean_{c,y<H-1,x} e^{-mean_ch |I(y+1,x) - I(y,x)|} (P(y+1,x) - P(y,x))^2
//      + mean_{c,y,x<W-1} e^{-mean_ch |I(y,x+1) - I(y,x)|} (P(y,x+1) - P(y,x))^2
// Applied to the transmitted colour, the depth and the normals; the guide is constant.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

class EdgeAwareTvLoss : public LossTermImpl<EdgeAwareTvLoss> {
 public:
  explicit EdgeAwareTvLoss(Buffer buffer = Buffer::kDepth, TargetKind guide = TargetKind::kImage)
      : buffer_(buffer), guide_(guide) {}
  std::string Name() const override {
    return std::string("tv(") + BufferName(buffer_) + ", " + TargetName(guide_) + ")";
  }
  std::vector<Buffer> Inputs() const override { return {buffer_}; }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), BufferName(buffer_), in.Get(buffer_)));
    return RequireImage(Name(), TargetName(guide_), SelectTarget(t, guide_), in.Get(buffer_), 3);
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& P = *in.Get(buffer_);
    const ImageT<T>& I = *SelectTarget(t, guide_);
    const int w = P.width(), h = P.height();
    if (w < 2 || h < 2) return 0.0;
    const double inv_v = 1.0 / (static_cast<double>(P.channels()) * (h - 1) * w);
    const double inv_h = 1.0 / (static_cast<double>(P.channels()) * h * (w - 1));
    auto edge = [&](int y0, int x0, int y1, int x1) {
      T d = 0;
      for (int c = 0; c < I.channels(); ++c) d += std::abs(I.at(c, y1, x1) - I.at(c, y0, x0));
      return std::exp(-d / static_cast<T>(I.channels()));
    };
    ImageT<T>* g = grad ? &grad->Get(buffer_, P) : nullptr;
    // Row y writes the gradient of rows y and y + 1: even rows in parallel, then odd rows, so no
    // two threads touch one row; per-row sums are added in row order, so the value does not depend
    // on the thread count either.
    std::vector<double> row_v(h, 0.0), row_h(h, 0.0);
    for (int parity = 0; parity < 2; ++parity) {
#pragma omp parallel for schedule(static) if (static_cast <int64_t>(w) * h >= 16384)
      for (int y = parity; y < h; y += 2) {
        double vertical = 0, horizontal = 0;
        for (int x = 0; x < w; ++x) {
          const T wv = y + 1 < h ? edge(y, x, y + 1, x) : T(0);
          const T wh = x + 1 < w ? edge(y, x, y, x + 1) : T(0);
          for (int c = 0; c < P.channels(); ++c) {
            if (y + 1 < h) {
              const T d = P.at(c, y + 1, x) - P.at(c, y, x);
              vertical += wv * d * d;
              if (g) {
                const T gd = static_cast<T>(2 * scale * inv_v) * wv * d;
                g->at(c, y + 1, x) += gd;
                g->at(c, y, x) -= gd;
              }
            }
            if (x + 1 < w) {
              const T d = P.at(c, y, x + 1) - P.at(c, y, x);
              horizontal += wh * d * d;
              if (g) {
                const T gd = static_cast<T>(2 * scale * inv_h) * wh * d;
                g->at(c, y, x + 1) += gd;
                g->at(c, y, x) -= gd;
              }
            }
          }
        }
        row_v[y] = vertical;
        row_h[y] = horizontal;
      }
    }
    double vertical = 0, horizontal = 0;
    for (int y = 0; y < h; ++y) {
      vertical += row_v[y];
      horizontal += row_h[y];
    }
    return vertical * inv_v + horizontal * inv_h;
  }

 private:
  Buffer buffer_;
  TargetKind guide_;
};

}  // namespace mgsr
