// Multi-view geometric consistency (after PGSR's forward-backward term): a pixel's rendered depth
// D, carried into a neighbouring view, meets the depth that view renders there; carried back from
// that surface, it must land on the pixel it came from.
//
//   L = sum over sampled pixels p (a grid of `stride`) and neighbours n of e_pn / M,
//   e_pn = |p' - p| (reference pixels), p' = pi_ref(X_n(pi_n(X_p))), X_p = C + D r_p,
//
// X_n(q) the neighbour's surface point at pixel q (its rendered depth, bilinear; a constant). Only
// D receives a gradient. A pair counts where e_pn is below `max_error_px` (beyond it the pixel is
// occluded in the neighbour or the surfaces disagree too much for a gradient to help) and the
// neighbour has depth there; M is the number of sampled foreground pixels (alpha and mask at least
// 0.5) times the number of neighbours. Needs the neighbours' rendered depth.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"
#include "mgsr/loss/multiview_geometry.h"
#include "mgsr/loss/parallel_pixels.h"

namespace mgsr {

struct MultiviewDepthConfig {
  int stride = 2;             // pixel grid of the samples
  double max_error_px = 2.0;  // pairs further apart do not count
  double min_alpha = 0.5;
};

class MultiviewDepthLoss : public LossTermImpl<MultiviewDepthLoss> {
 public:
  explicit MultiviewDepthLoss(const MultiviewDepthConfig& config = {}) : c_(config) {}
  std::string Name() const override { return "multiview_depth"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kDepth}; }
  std::vector<Buffer> ConstantInputs() const override { return {Buffer::kAlpha}; }
  bool ReadsNeighbourDepth() const override { return true; }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), "depth", in.Get(Buffer::kDepth),
                                      static_cast<const Image*>(nullptr), 1));
    MGSR_RETURN_IF_ERROR(
        RequireImage(Name(), "alpha", in.Get(Buffer::kAlpha), in.Get(Buffer::kDepth), 1));
    if (t.mask != nullptr)
      MGSR_RETURN_IF_ERROR(RequireImage(Name(), "mask", t.mask, in.Get(Buffer::kDepth), 1));
    if (in.camera == nullptr) return Status::Error(Name() + ": needs the camera");
    for (int k = 0; k < t.num_neighbours; ++k) {
      if (t.neighbours[k].camera == nullptr || t.neighbours[k].depth == nullptr)
        return Status::Error(Name() + ": neighbour " + std::to_string(k) +
                             " has no rendered depth");
    }
    return Status::Ok();
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& D = *in.Get(Buffer::kDepth);
    const ImageT<T>& A = *in.Get(Buffer::kAlpha);
    const Camera& cam = *in.camera;
    const int w = D.width(), h = D.height(), stride = std::max(1, c_.stride);
    const int rows = multiview::GridCells(h, stride);
    const size_t centres = multiview::CountSampledPixels(A, t.mask, stride, c_.min_alpha);
    if (centres == 0 || t.num_neighbours == 0) return 0.0;
    const double inv_count = 1.0 / (static_cast<double>(centres) * t.num_neighbours);
    T* gD = grad != nullptr ? grad->Get(Buffer::kDepth, D).data() : nullptr;
    static thread_local std::vector<double> row_sums;
    row_sums.assign(rows, 0.0);
    // A pointer, not the thread_local, into the parallel region (each thread's own is empty).
    double* const sums = row_sums.data();
#pragma omp parallel for schedule(dynamic, 4) if (static_cast <int64_t>(w) * h >= kParallelPixels)
    for (int row = 0; row < rows; ++row) {
      const int y = row * stride;
      double sum = 0;
      for (int x = 0; x < w; x += stride) {
        const size_t i = static_cast<size_t>(y) * w + x;
        if (!multiview::SampledPixel(A, t.mask, i, c_.min_alpha)) continue;
        const double depth = D.data()[i];
        if (!(depth > 0)) continue;
        double d_depth = 0;
        for (int k = 0; k < t.num_neighbours; ++k) {
          double e, de;
          if (!multiview::ForwardBackward(cam, *t.neighbours[k].camera, *t.neighbours[k].depth,
                                          Eigen::Vector2d(x + 0.5, y + 0.5), depth, &e, &de))
            continue;
          if (e > c_.max_error_px) continue;
          sum += e;
          d_depth += de;
        }
        if (gD != nullptr) gD[i] += static_cast<T>(scale * inv_count * d_depth);
      }
      sums[row] = sum;
    }
    double total = 0;
    for (int row = 0; row < rows; ++row) total += sums[row];
    return total * inv_count;
  }

  const MultiviewDepthConfig& config() const { return c_; }

 private:
  MultiviewDepthConfig c_;
};

}  // namespace mgsr
