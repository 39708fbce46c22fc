// BM_LossSet3D / BM_LossSet2D: the full loss sets of the two branches (value and gradient) at
// 256 and 512 pixels, BM_PhotoRow (the exposure-compensated render loss) and BM_Dssim alone, to
// compare with the rasterizer's forward+backward (D-SSIM should stay well under a quarter of it);
// BM_MultiviewNcc, the multi-view patch term (on by default) against two neighbours, on a textured
// plane seen exactly, so that every patch passes its tests and is compared.
// Argument: image width (square images).
#include <benchmark/benchmark.h>

#include "mgsr/core/rng.h"
#include "mgsr/loss/dssim_loss.h"
#include "mgsr/loss/edge_aware_tv_loss.h"
#include "mgsr/loss/exposure_compensation.h"
#include "mgsr/loss/multiview_ncc_loss.h"
#include "mgsr/loss/mutual_depth_loss.h"
#include "mgsr/loss/normal_consistency_loss.h"
#include "mgsr/loss/problem.h"
#include "mgsr/loss/render_loss.h"
#include "shell_scene.h"

namespace {

struct Inputs {
  mgsr::Camera camera;
  std::array<mgsr::Image, mgsr::kNumBuffers> buffers;
  mgsr::Image image, transmitted, mask, other_depth;
  mgsr::RenderBuffers in;
  mgsr::Targets targets;
  explicit Inputs(int w) : camera(mgsr::bench::ShellCamera(w)) {
    mgsr::Rng rng(1);
    auto random = [&](int c, double lo, double hi) {
      mgsr::Image im(w, w, c);
      for (size_t i = 0; i < im.size(); ++i) im.data()[i] = static_cast<float>(rng.Uniform(lo, hi));
      return im;
    };
    for (int b = 0; b < mgsr::kNumBuffers; ++b) {
      const auto buf = static_cast<mgsr::Buffer>(b);
      buffers[b] = buf == mgsr::Buffer::kDepth ? random(1, 2.5, 3.5)
                                               : random(mgsr::BufferChannels(buf), 0, 1);
      in.Set(buf, &buffers[b]);
    }
    in.camera = &camera;
    image = random(3, 0, 1);
    transmitted = random(3, 0, 1);
    mask = random(1, 0, 1);
    other_depth = random(1, 2.5, 3.5);
    targets = {&image, &mask, &transmitted, &other_depth};
  }
};

// The mutual-stage loss sets (method.md 1.5): 3DGS render + mutual depth; 2DGS mutual render,
// normal consistency, normal TV and depth TV.
mgsr::Problem MakeProblem() {
  using mgsr::Branch;
  using mgsr::Buffer;
  using mgsr::TargetKind;
  mgsr::Problem p;
  p.AddTerm(std::make_unique<mgsr::RenderLoss>(), 0.5, Branch::kGaussians3D);
  p.AddTerm(std::make_unique<mgsr::MutualDepthLoss>(), 0.01, Branch::kGaussians3D);
  p.AddTerm(std::make_unique<mgsr::MutualRenderLoss>(), 0.5, Branch::kSurfels2D);
  p.AddTerm(std::make_unique<mgsr::NormalConsistencyLoss>(), 0.025, Branch::kSurfels2D);
  p.AddTerm(std::make_unique<mgsr::EdgeAwareTvLoss>(Buffer::kNormal, TargetKind::kTransmitted),
            0.025, Branch::kSurfels2D);
  p.AddTerm(std::make_unique<mgsr::EdgeAwareTvLoss>(Buffer::kDepth, TargetKind::kTransmitted),
            0.025, Branch::kSurfels2D);
  return p;
}

// A textured plane through the origin seen by a view and two neighbours (square, `w` pixels):
// rendered depth, normal and alpha of the view, grey photos of all three.
struct PlaneViews {
  mgsr::Camera view, nb[2];
  mgsr::Image depth, normal, alpha, gray[3];
  mgsr::RenderBuffers in;
  mgsr::Targets targets;
  explicit PlaneViews(int w)
      : view(mgsr::bench::ShellCamera(w)),
        nb{mgsr::LookAtCamera({1.0, -2.8, 0.8}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), w, w, view.fx,
                              view.fy),
           mgsr::LookAtCamera({-0.4, -2.9, 0.2}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), w, w, view.fx,
                              view.fy)},
        depth(w, w, 1),
        normal(w, w, 3),
        alpha(w, w, 1) {
    const Eigen::Vector3d n = Eigen::Vector3d(0.15, -1.0, 0.3).normalized();
    const mgsr::Camera* cams[3] = {&view, &nb[0], &nb[1]};
    for (int c = 0; c < 3; ++c) {
      gray[c] = mgsr::Image(w, w, 1);
      const Eigen::Vector3d C = cams[c]->Center();
      for (int y = 0; y < w; ++y) {
        for (int x = 0; x < w; ++x) {
          const Eigen::Vector3d r = cams[c]->R.transpose() * cams[c]->PixelToRay(x + 0.5, y + 0.5);
          const double t = -n.dot(C) / n.dot(r);  // z-depth: r has camera z = 1
          const Eigen::Vector3d X = C + t * r;
          gray[c].at(0, y, x) = static_cast<float>(
              0.5 + 0.2 * std::sin(21 * X.x() + 4 * X.y()) * std::cos(15 * X.z() - 1.2 * X.x()) +
              0.15 * std::sin(33 * X.y() + 9 * X.z()));
          if (c > 0) continue;
          depth.at(0, y, x) = static_cast<float>(t);
          for (int k = 0; k < 3; ++k) normal.at(k, y, x) = static_cast<float>(-n[k]);
          alpha.at(0, y, x) = 1.0f;
        }
      }
    }
    in.camera = &view;
    in.Set(mgsr::Buffer::kDepth, &depth);
    in.Set(mgsr::Buffer::kNormal, &normal);
    in.Set(mgsr::Buffer::kAlpha, &alpha);
    targets.gray = &gray[0];
    for (int k = 0; k < 2; ++k) targets.neighbours[k] = {&nb[k], &gray[k + 1], nullptr};
    targets.num_neighbours = 2;
  }
};

void BM_MultiviewNcc(benchmark::State& state) {
  PlaneViews v(static_cast<int>(state.range(0)));
  const mgsr::MultiviewNccLoss term;
  mgsr::RenderGradients g;
  for (auto _ : state) benchmark::DoNotOptimize(term.Evaluate(v.in, v.targets, 1.0, &g));
}

void BM_LossSet3D(benchmark::State& state) {
  Inputs in(static_cast<int>(state.range(0)));
  const mgsr::Problem p = MakeProblem();
  mgsr::RenderGradients g;
  for (auto _ : state)
    benchmark::DoNotOptimize(p.Evaluate(mgsr::Branch::kGaussians3D, in.in, in.targets, &g));
}
void BM_LossSet2D(benchmark::State& state) {
  Inputs in(static_cast<int>(state.range(0)));
  const mgsr::Problem p = MakeProblem();
  mgsr::RenderGradients g;
  for (auto _ : state)
    benchmark::DoNotOptimize(p.Evaluate(mgsr::Branch::kSurfels2D, in.in, in.targets, &g));
}
void BM_Dssim(benchmark::State& state) {
  Inputs in(static_cast<int>(state.range(0)));
  const mgsr::DssimLoss dssim;
  mgsr::RenderGradients g;
  for (auto _ : state) benchmark::DoNotOptimize(dssim.Evaluate(in.in, in.targets, 1.0, &g));
}

// The photometric row as training runs it: the render loss (L1 + D-SSIM) of the exposure-
// compensated colour (an affine colour transform, masked) against the photo.
void BM_PhotoRow(benchmark::State& state) {
  Inputs in(static_cast<int>(state.range(0)));
  const mgsr::ColorTransform transform = {1.1,   0.05, -0.02, 0.03, 0.9,   0.01,
                                          -0.04, 0.02, 1.05,  0.02, -0.01, 0.03};
  const mgsr::ExposureCompensatedLoss photo(std::make_unique<mgsr::RenderLoss>(), transform);
  mgsr::RenderGradients g;
  for (auto _ : state) benchmark::DoNotOptimize(photo.Evaluate(in.in, in.targets, 1.0, &g));
}
// Widths up to 1440, the pixels of a 1920 x 1080 photo; the rows run on all threads: wall time.
void PhotoSizes(benchmark::internal::Benchmark* b) {
  b->Arg(256)->Arg(512)->Arg(1440)->ArgName("width")->Unit(benchmark::kMillisecond)->UseRealTime();
}
BENCHMARK(BM_PhotoRow)->Apply(PhotoSizes);

// One edge-aware TV term (depth: 1 channel; normals: 3), guided by a colour image: about 0.6 /
// 1.0 ms at 256 px on this machine, a few percent of BM_LossSet2D (a vectorised rewrite with a
// polynomial exp measured 0.46-0.67 / 0.54 ms, and slower at 512 px: not kept).
void BM_EdgeAwareTv(benchmark::State& state) {
  Inputs in(static_cast<int>(state.range(0)));
  const mgsr::EdgeAwareTvLoss tv(state.range(1) == 1 ? mgsr::Buffer::kDepth : mgsr::Buffer::kNormal,
                                 mgsr::TargetKind::kTransmitted);
  mgsr::RenderGradients g;
  for (auto _ : state) benchmark::DoNotOptimize(tv.Evaluate(in.in, in.targets, 1.0, &g));
}

BENCHMARK(BM_LossSet3D)->Arg(256)->Arg(512)->ArgName("width")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_LossSet2D)->Arg(256)->Arg(512)->ArgName("width")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MultiviewNcc)
    ->Arg(256)
    ->Arg(512)
    ->Arg(1024)
    ->ArgName("width")
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EdgeAwareTv)
    ->ArgsProduct({{256, 512}, {1, 3}})
    ->ArgNames({"width", "channels"})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Dssim)->Arg(128)->Apply(PhotoSizes);

}  // namespace
