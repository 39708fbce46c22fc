// Depth-normal consistency of the 2DGS branch (reference 1.3, 3.6; paper eq. 10):
//   L_n = mean_pixels gamma (1 - <N_rend, stopgrad(A) N_surf>)
// N_rend is the alpha-weighted world normal; N_surf the unit normal of the surface the expected
// depth describes: back-project pixel centres P = C + D r (r the world ray with camera z = 1),
// N_surf = normalise((P(y+1) - P(y-1)) x (P(x+1) - P(x-1))), zero on the border. gamma is the
// foreground mask (1 without one). Gradients reach the normals and, through N_surf, the depth.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {

// World-space unit normals from a depth map (3 channels; zero where undefined).
template <typename T>
ImageT<T> DepthToNormal(const ImageT<T>& depth, const Camera& camera);

class NormalConsistencyLoss : public LossTermImpl<NormalConsistencyLoss> {
 public:
  std::string Name() const override { return "normal_consistency"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kNormal, Buffer::kDepth}; }
  std::vector<Buffer> ConstantInputs() const override { return {Buffer::kAlpha}; }
  Status Check(const RenderBuffers& in, const Targets& t) const override {
    MGSR_RETURN_IF_ERROR(RequireImage(Name(), "depth", in.Get(Buffer::kDepth),
                                      static_cast<const Image*>(nullptr), 1));
    MGSR_RETURN_IF_ERROR(
        RequireImage(Name(), "normal", in.Get(Buffer::kNormal), in.Get(Buffer::kDepth), 3));
    MGSR_RETURN_IF_ERROR(
        RequireImage(Name(), "alpha", in.Get(Buffer::kAlpha), in.Get(Buffer::kDepth), 1));
    if (t.mask != nullptr)
      MGSR_RETURN_IF_ERROR(RequireImage(Name(), "mask", t.mask, in.Get(Buffer::kDepth), 1));
    if (in.camera == nullptr) return Status::Error(Name() + ": needs the camera");
    return Status::Ok();
  }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const;
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
  using V = internal::Vec3<T>;
  const ImageT<T>& D = *in.Get(Buffer::kDepth);
  const ImageT<T>& N = *in.Get(Buffer::kNormal);
  const ImageT<T>& A = *in.Get(Buffer::kAlpha);
  const Camera& cam = *in.camera;
  const int w = D.width(), h = D.height();
  const double inv_n = 1.0 / (static_cast<double>(w) * h);
  const V C = cam.Center().template cast<T>();
  // World rays of every pixel, once per call, and per-row sums: scratch kept per thread between
  // calls (no allocation once sized). Only pointers go into the parallel region below (a worker
  // thread naming a thread_local would get its own).
  static thread_local std::vector<V> ray_storage;
  static thread_local std::vector<double> row_storage;
  ray_storage.resize(static_cast<size_t>(w) * h);
  row_storage.assign(h, 0.0);
  V* const rays = ray_storage.data();
  double* const row_total = row_storage.data();
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x)
      rays[static_cast<size_t>(y) * w + x] = internal::PixelRay<T>(cam, x, y);
  }
  auto ray = [&](int x, int y) -> const V& { return rays[static_cast<size_t>(y) * w + x]; };
  auto P = [&](int x, int y) -> V { return C + D.at(0, y, x) * ray(x, y); };
  ImageT<T>* gN = grad ? &grad->Get(Buffer::kNormal, N) : nullptr;
  ImageT<T>* gD = grad ? &grad->Get(Buffer::kDepth, D) : nullptr;
  // Pixel (x, y) writes the depth gradient of rows y - 1 .. y + 1: rows are processed in three
  // interleaved phases (y mod 3), each in parallel, so no two threads touch one row; per-row sums
  // are added in row order (deterministic for any thread count).
  for (int phase = 0; phase < 3; ++phase) {
#pragma omp parallel for schedule(static) if (static_cast <int64_t>(w) * h >= 16384)
    for (int y = phase; y < h; y += 3) {
      double total = 0;
      for (int x = 0; x < w; ++x) {
        const T gamma = t.mask != nullptr ? t.mask->at(0, y, x) : T(1);
        const V n_rend(N.at(0, y, x), N.at(1, y, x), N.at(2, y, x));
        const bool interior = x > 0 && y > 0 && x + 1 < w && y + 1 < h;
        V dy = V::Zero(), dx = V::Zero(), c = V::Zero();
        T len = 0;
        if (interior) {
          dy = P(x, y + 1) - P(x, y - 1);
          dx = P(x + 1, y) - P(x - 1, y);
          c = dy.cross(dx);
          len = c.norm();
        }
        const bool defined = interior && len > T(0);
        const V n_surf = defined ? V(c / len) : V::Zero();
        const T a = A.at(0, y, x);  // held constant (stop-gradient)
        total += gamma * (1 - n_rend.dot(n_surf) * a);
        if (!grad || gamma == T(0)) continue;
        const T s = static_cast<T>(-scale * inv_n) * gamma * a;
        for (int k = 0; k < 3; ++k) gN->at(k, y, x) += s * n_surf[k];
        if (!defined) continue;
        // d/d n_surf = s n_rend -> through the normalisation -> the cross product -> the four
        // depths.
        const V dn = s * n_rend;
        const V dc = (dn - n_surf * n_surf.dot(dn)) / len;
        const V d_dy = dx.cross(dc);  // c = dy x dx
        const V d_dx = dc.cross(dy);
        gD->at(0, y + 1, x) += d_dy.dot(ray(x, y + 1));
        gD->at(0, y - 1, x) -= d_dy.dot(ray(x, y - 1));
        gD->at(0, y, x + 1) += d_dx.dot(ray(x + 1, y));
        gD->at(0, y, x - 1) -= d_dx.dot(ray(x - 1, y));
      }
      row_total[y] = total;
    }
  }
  double total = 0;
  for (int y = 0; y < h; ++y) total += row_total[y];
  return total * inv_n;
}

}  // namespace mgsr
