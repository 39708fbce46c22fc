// Object-like benchmark scenes: primitives spread over a sphere of radius 1 (a shell), seen from
// distance 3, with scales matched to the spacing of the points, as a trained object model has.
#pragma once

#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/profiler.h"
#include "mgsr/core/rng.h"
#include "mgsr/model/gaussian_model.h"
#include "mgsr/model/surfel_model.h"
#include "mgsr/render/rasterize_gaussians.h"
#include "mgsr/render/rasterize_surfels.h"

namespace mgsr::bench {

inline Camera ShellCamera(int width) {
  const double fx = width / (2 * std::tan(0.5 * 0.8));  // 46 degree field of view
  return LookAtCamera({0.4, -2.9, 0.6}, {0, 0, 0}, Eigen::Vector3d::UnitZ(), width, width, fx, fx);
}

inline GaussianModel ShellGaussians(int count, uint64_t seed) {
  Rng rng(seed);
  GaussianModel m;
  m.max_sh_degree = 3;
  m.Resize(count);
  const double spacing = std::sqrt(4 * M_PI / count);
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d p(rng.Normal(), rng.Normal(), rng.Normal());
    p = p.normalized() * (1.0 + rng.Normal(0, 0.01));
    for (int k = 0; k < 3; ++k) m.means[3 * i + k] = static_cast<float>(p[k]);
    m.log_scales[3 * i] = static_cast<float>(std::log(spacing * rng.Uniform(0.7, 1.5)));
    m.log_scales[3 * i + 1] = static_cast<float>(std::log(spacing * rng.Uniform(0.7, 1.5)));
    m.log_scales[3 * i + 2] = static_cast<float>(std::log(spacing * 0.2));
    for (int k = 0; k < 4; ++k) m.quats[4 * i + k] = static_cast<float>(rng.Normal());
    m.opacity_logits[i] = static_cast<float>(rng.Uniform(0.0, 3.0));
    m.ref_opacity_logits[i] = static_cast<float>(rng.Uniform(-3.0, 0.0));
    m.beta_logits[i] = static_cast<float>(rng.Uniform(-3.0, 0.0));
  }
  for (float& v : m.sh) v = static_cast<float>(rng.Normal(0, 0.2));
  for (float& v : m.ref_sh) v = static_cast<float>(rng.Normal(0, 0.2));
  return m;
}

// Surfels on the same shell, oriented along the surface (normal = radial direction).
inline SurfelModel ShellSurfels(int count, uint64_t seed) {
  Rng rng(seed);
  SurfelModel m;
  m.max_sh_degree = 3;
  m.Resize(count);
  const double spacing = std::sqrt(4 * M_PI / count);
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d p(rng.Normal(), rng.Normal(), rng.Normal());
    p.normalize();
    const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), p);
    p *= 1.0 + rng.Normal(0, 0.01);
    for (int k = 0; k < 3; ++k) m.means[3 * i + k] = static_cast<float>(p[k]);
    m.log_scales[2 * i] = static_cast<float>(std::log(spacing * rng.Uniform(0.7, 1.5)));
    m.log_scales[2 * i + 1] = static_cast<float>(std::log(spacing * rng.Uniform(0.7, 1.5)));
    m.quats[4 * i] = static_cast<float>(q.w());
    m.quats[4 * i + 1] = static_cast<float>(q.x());
    m.quats[4 * i + 2] = static_cast<float>(q.y());
    m.quats[4 * i + 3] = static_cast<float>(q.z());
    m.opacity_logits[i] = static_cast<float>(rng.Uniform(0.0, 3.0));
  }
  for (float& v : m.sh) v = static_cast<float>(rng.Normal(0, 0.2));
  return m;
}

// The argument grid of the render benchmarks: width 256 and 512, 10k and 100k primitives, 1 and 2
// threads, reported in milliseconds of wall time.
inline void RenderBenchmarkArgs(benchmark::internal::Benchmark* b) {
  for (int width : {256, 512}) {
    for (int count : {10000, 100000}) {
      for (int threads : {1, 2}) b->Args({width, count, threads});
    }
  }
  b->ArgNames({"width", "count", "threads"})->Unit(benchmark::kMillisecond)->UseRealTime();
}

// Real photo sizes: 1440 x 1440 px (2.07 MP, the pixels of a 1920 x 1080 photo; the shell is
// square) with 250,000 primitives, 1 and 2 threads: where binning, the backward's per-pixel state
// and memory traffic weigh more than at 256 px.
inline void RealSizeBenchmarkArgs(benchmark::internal::Benchmark* b) {
  for (int threads : {1, 2}) b->Args({1440, 250000, threads});
  b->ArgNames({"width", "count", "threads"})->Unit(benchmark::kMillisecond)->UseRealTime();
}

// The argument grid of the *Stages benchmarks: 256 px, 10k and 100k primitives, 1 and 2 threads.
inline void StageBenchmarkArgs(benchmark::internal::Benchmark* b) {
  for (int count : {10000, 100000}) {
    for (int threads : {1, 2}) b->Args({256, count, threads});
  }
  b->ArgNames({"width", "count", "threads"})->Unit(benchmark::kMillisecond)->UseRealTime();
}

// For the *Stages benchmarks, which run a render's forward and backward with the renderers'
// profile scopes on: each stage's time (projection & SH, binning, raster forward and backward,
// projection & SH backward) in ms per iteration, as counters ("projection+SH_ms", ...). The
// headline benchmarks run without the profiler's clock reads.
class StageCounters {
 public:
  StageCounters() {
    Profiler::Take();  // whatever an earlier benchmark left
    Profiler::SetEnabled(true);
  }
  void Report(benchmark::State& state) {
    Profiler::SetEnabled(false);
    for (const ProfileEntry& e : Profiler::Take()) {
      std::string name;
      for (size_t i = 0; i < e.name.size(); ++i) {
        if (e.name.compare(i, 3, " & ") == 0) {
          name += '+';
          i += 2;
        } else {
          name += e.name[i] == ' ' ? '_' : e.name[i];
        }
      }
      state.counters[name + "_ms"] =
          1e3 * e.seconds / static_cast<double>(std::max<int64_t>(1, state.iterations()));
    }
  }
};

inline uint64_t SumOf(const std::vector<uint32_t>& v) {
  uint64_t s = 0;
  for (uint32_t x : v) s += x;
  return s;
}
inline uint64_t PairsWalked(const GaussianRender& r) { return SumOf(r.last_t) + SumOf(r.last_r); }
inline uint64_t PairsWalked(const SurfelRender& r) { return SumOf(r.last); }

// The body of a *Stages benchmark: one untimed forward+backward (it grows the buffers), then the
// timed loop with StageCounters. `Fixture` has model, options and grad (the upstream gradient).
template <class Renderer, class Render, class Gradients, class Fixture>
void RunStages(benchmark::State& state, const Fixture& f) {
  Renderer renderer;
  Render out;
  Gradients grads;
  renderer.Forward(f.model, f.options, &out);
  renderer.Backward(f.model, f.options, out, f.grad, &grads);
  StageCounters stages;
  for (auto _ : state) {
    renderer.Forward(f.model, f.options, &out);
    renderer.Backward(f.model, f.options, out, f.grad, &grads);
    benchmark::DoNotOptimize(grads.params.means.data());
  }
  stages.Report(state);
  // The pixel-primitive pairs the forward walked (per pixel, the tile-list entries up to its last
  // blended one, in each chain), in millions: the work the raster times are spent on.
  state.counters["pairs_M"] = static_cast<double>(PairsWalked(out)) * 1e-6;
}

}  // namespace mgsr::bench
