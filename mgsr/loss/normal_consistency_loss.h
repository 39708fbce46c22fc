// Depth-normal consistency of the 2DGS branch (method.md 1.3, 3.6; paper eq. 10):
//   L_n = mean_pixels gamma (1 - <N_rend, stopgrad(A) N_surf>)
// N_rend is the alpha-weighted world normal; N_surf the unit normal of the surface the expected
// depth describes: back-project pixel centres P = C + D r (r the world ray with camera z = 1),
// N_surf = normalise((P(y+1) - P(y-1)) x (P(x+1) - P(x-1))), zero on the border; with one_sided,
// along an axis with a depth step the difference is P(x+1) - P(x) or P(x) - P(x-1), towards the
// closer neighbour. gamma is the foreground mask (1 without one). Gradients reach the normals
// and, through N_surf, the depth.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"
#include "mgsr/loss/multiview_geometry.h"
#include "mgsr/loss/multiview_ncc_loss.h"
#include "mgsr/loss/normal_consistency_plane.h"
#include "mgsr/loss/parallel_pixels.h"

namespace mgsr {

// World-space unit normals from a depth map (3 channels; zero where undefined).
template <typename T>
ImageT<T> DepthToNormal(const ImageT<T>& depth, const Camera& camera);

// The variants of the depth-normal consistency (docs/geometry.md measures each).
struct NormalConsistencyOptions {
  // false: the depth's normal N_surf is a constant target too, so the term turns the rendered
  // normals towards the surface without pulling the depth (whose finite differences round off
  // creases and fill concavities).
  bool depth_gradient = true;
  // beta > 0: each pixel's term is weighted by exp(-beta g), g the photo's mean absolute central
  // difference there (both axes, all channels): the prior relaxes where the photo shows an edge
  // (a crease, a groove's rim) and holds where the photo is flat.
  double edge_weight = 0;
  // sigma > 0: each pixel's residual r enters as sigma r / (r + sigma), the same as r where the
  // normals nearly agree but bounded by sigma, with a pull that fades as (sigma / (r + sigma))^2.
  double robust_scale = 0;
  // true: along an axis where one neighbour's depth jump from the centre exceeds the other's by
  // kNormalStepRatio (a tooth in front of a groove, the backdrop at the outline), N_surf takes the
  // one-sided difference towards the closer neighbour, so neither side of the step gets its
  // slanted normal, which would pull their depths together; central differences elsewhere.
  bool one_sided = false;
  // f < 1: each pixel's term is weighted by 1 - (1 - f) a, a in [0, 1] how well the neighbouring
  // photos agree with the rendered plane there (MultiviewNccLoss::Agreement, at the nearest centre
  // of its grid): the prior keeps its full weight where the views cannot place the surface (no
  // texture, no neighbour, a plane they contradict) and falls to f where they pin it. A constant
  // of each step, like the mask: no gradient flows through it. 1: off.
  double agreement_floor = 1;
};

class NormalConsistencyLoss : public LossTermImpl<NormalConsistencyLoss> {
 public:
  explicit NormalConsistencyLoss(const NormalConsistencyOptions& options = {})
      : depth_gradient_(options.depth_gradient),
        edge_weight_(options.edge_weight),
        robust_scale_(options.robust_scale),
        one_sided_(options.one_sided),
        agreement_floor_(options.agreement_floor),
        agreement_(AgreementConfig()) {}
  std::string Name() const override { return "normal_consistency"; }
  std::vector<Buffer> Inputs() const override {
    if (!depth_gradient_) return {Buffer::kNormal};
    return {Buffer::kNormal, Buffer::kDepth};
  }
  std::vector<Buffer> ConstantInputs() const override {
    if (!depth_gradient_) return {Buffer::kAlpha, Buffer::kDepth};
    return {Buffer::kAlpha};
  }
  bool ReadsNeighbours() const override { return agreement_floor_ < 1; }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    return RequireSurfaceGeometry(Name(), in, t);
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const;

  // Each pixel's weight in the sum (the mask gamma, times the edge and agreement weights when
  // they are on) into `weight` (w x h); false, and `weight` untouched, when it is just the mask.
  template <typename T>
  bool PixelWeights(const RenderBuffersT<T>& in, const TargetsT<T>& t,
                    std::vector<T>* weight) const;

  // The patch comparison behind the agreement weight: the patch term's, except that a patch
  // counts where its rendered points lie within 2 pixel footprints of their own fitted plane.
  // With the term's own test (1 footprint from the plane of the centre's rendered normal) the
  // weight hardly moved: on the gear's warm-up 6 to 9 in 10 foreground cells had no comparison
  // (docs/geometry.md, "A normal prior that follows the views' agreement"); this one still
  // leaves out patches across outlines, steps and tight curves.
  static MultiviewNccConfig AgreementConfig() {
    MultiviewNccConfig c;
    c.fit_plane = true;
    c.max_plane_offset_px = 2.0;
    return c;
  }

 private:
  bool depth_gradient_ = true;
  double edge_weight_ = 0;
  double robust_scale_ = 0;
  bool one_sided_ = false;
  double agreement_floor_ = 1;
  MultiviewNccLoss agreement_;
};

// --- implementation ---------------------------------------------------------------------------

namespace internal {
template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

// World ray (camera z = 1) through the centre of pixel (x, y).
template <typename T>
Vec3<T> PixelRay(const Camera& cam, int x, int y) {
  return (cam.R.transpose() * cam.PixelToRay(x + 0.5, y + 0.5)).template cast<T>();
}
}  // namespace internal

template <typename T>
ImageT<T> DepthToNormal(const ImageT<T>& depth, const Camera& cam) {
  using V = internal::Vec3<T>;
  const int w = depth.width(), h = depth.height();
  ImageT<T> out(w, h, 3);
  const V C = cam.Center().template cast<T>();
  auto P = [&](int x, int y) -> V {
    return C + depth.at(0, y, x) * internal::PixelRay<T>(cam, x, y);
  };
  for (int y = 1; y + 1 < h; ++y) {
    for (int x = 1; x + 1 < w; ++x) {
      const V c = (P(x, y + 1) - P(x, y - 1)).cross(P(x + 1, y) - P(x - 1, y));
      const T len = c.norm();
      if (!(len > T(0))) continue;
      for (int k = 0; k < 3; ++k) out.at(k, y, x) = c[k] / len;
    }
  }
  return out;
}

template <typename T>
double NormalConsistencyLoss::Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t,
                                      double scale, RenderGradientsT<T>* grad) const {
  const ImageT<T>& D = *in.Get(Buffer::kDepth);
  const ImageT<T>& N = *in.Get(Buffer::kNormal);
  const ImageT<T>& A = *in.Get(Buffer::kAlpha);
  const Camera& cam = *in.camera;
  const int w = D.width(), h = D.height();
  const size_t n = static_cast<size_t>(w) * h;
  const double inv_n = 1.0 / static_cast<double>(n);
  // World rays of every pixel (three planes), once per call: scratch kept between calls (no
  // allocation once sized). The pixel loop is NormalConsistencySum (normal_consistency_plane.h).
  static thread_local std::vector<T> ray_storage;
  ray_storage.resize(3 * n);
  T* const rays = ray_storage.data();
#pragma omp parallel for schedule(static) if (static_cast <int64_t>(n) >= kParallelPixels)
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const internal::Vec3<T> r = internal::PixelRay<T>(cam, x, y);
      const size_t i = static_cast<size_t>(y) * w + x;
      for (int k = 0; k < 3; ++k) rays[k * n + i] = r[k];
    }
  }
  NormalConsistencyPlanes<T> p;
  p.width = w;
  p.height = h;
  p.depth = D.data();
  p.alpha = A.data();
  p.mask = t.mask != nullptr ? t.mask->data() : nullptr;
  p.robust_scale = static_cast<T>(robust_scale_);
  p.one_sided = one_sided_;
  static thread_local std::vector<T> weight;
  if (PixelWeights(in, t, &weight)) p.mask = weight.data();
  const internal::Vec3<T> C = cam.Center().template cast<T>();
  for (int k = 0; k < 3; ++k) {
    p.normal[k] = N.plane(k);
    p.ray[k] = rays + k * n;
    p.center[k] = C[k];
  }
  if (grad != nullptr) {
    ImageT<T>& gN = grad->Get(Buffer::kNormal, N);
    for (int k = 0; k < 3; ++k) p.d_normal[k] = gN.plane(k);
    if (depth_gradient_) {
      p.d_depth = grad->Get(Buffer::kDepth, D).data();
    } else {
      // The kernel writes a depth gradient; here it goes into scratch and is dropped.
      static thread_local std::vector<T> dropped;
      dropped.assign(n, T(0));
      p.d_depth = dropped.data();
    }
    p.gain = static_cast<T>(-scale * inv_n);
  }
  return NormalConsistencySum(p) * inv_n;
}

template <typename T>
bool NormalConsistencyLoss::PixelWeights(const RenderBuffersT<T>& in, const TargetsT<T>& t,
                                         std::vector<T>* weight) const {
  const ImageT<T>& D = *in.Get(Buffer::kDepth);
  const int w = D.width(), h = D.height();
  const size_t n = static_cast<size_t>(w) * h;
  const bool edges =
      edge_weight_ > 0 && t.image != nullptr && t.image->width() == w && t.image->height() == h;
  const bool agreement = agreement_floor_ < 1 && t.gray != nullptr && t.num_neighbours > 0;
  if (!edges && !agreement) return false;
  weight->resize(n);
  T* const out = weight->data();
  const T* const mask = t.mask != nullptr ? t.mask->data() : nullptr;
  for (size_t i = 0; i < n; ++i) out[i] = mask != nullptr ? mask[i] : T(1);
  if (edges) {
    // exp(-beta g): a constant of the photo, like the mask itself.
    const ImageT<T>& I = *t.image;
    const int channels = I.channels();
#pragma omp parallel for schedule(static) if (static_cast <int64_t>(n) >= kParallelPixels)
    for (int y = 0; y < h; ++y) {
      const int y0 = y > 0 ? y - 1 : y, y1 = y + 1 < h ? y + 1 : y;
      for (int x = 0; x < w; ++x) {
        const int x0 = x > 0 ? x - 1 : x, x1 = x + 1 < w ? x + 1 : x;
        double g = 0;
        for (int c = 0; c < channels; ++c) {
          const T* plane = I.plane(c);
          g += std::abs(static_cast<double>(plane[y * w + x1] - plane[y * w + x0])) +
               std::abs(static_cast<double>(plane[y1 * w + x] - plane[y0 * w + x]));
        }
        g /= 2.0 * channels;
        const size_t i = static_cast<size_t>(y) * w + x;
        out[i] = static_cast<T>(static_cast<double>(out[i]) * std::exp(-edge_weight_ * g));
      }
    }
  }
  if (agreement) {
    static thread_local std::vector<double> cells;
    agreement_.Agreement(in, t, &cells);
    const int s = agreement_.Stride(w, h);
    const int cols = multiview::GridCells(w, s), rows = multiview::GridCells(h, s);
    const double drop = 1.0 - agreement_floor_;
    for (int y = 0; y < h; ++y) {
      const int cy = std::min(rows - 1, (y + s / 2) / s);
      for (int x = 0; x < w; ++x) {
        const int cx = std::min(cols - 1, (x + s / 2) / s);
        const size_t i = static_cast<size_t>(y) * w + x;
        const double a = cells[static_cast<size_t>(cy) * cols + cx];
        out[i] = static_cast<T>(static_cast<double>(out[i]) * (1.0 - drop * a));
      }
    }
  }
  return true;
}

}  // namespace mgsr
