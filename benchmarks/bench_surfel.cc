// BM_SurfelForward / BM_SurfelForwardBackward (BM_SurfelStages: the latter per stage): the
// 2DGS-branch render on an object-like scene (surfels tangent to a shell of radius 1 seen from
// distance 3, scales matched to the spacing, SH degree 3). Arguments: image width (square images),
// surfel count, threads.
#include <benchmark/benchmark.h>
#include <omp.h>

#include "mgsr/core/rng.h"
#include "mgsr/render/surfel_renderer.h"
#include "shell_scene.h"

namespace {

struct Fixture {
  mgsr::SurfelModel model;
  mgsr::SurfelRenderOptions options;
  mgsr::SurfelRenderGrad grad;
};

Fixture MakeFixture(int width, int count) {
  Fixture f;
  f.model = mgsr::bench::ShellSurfels(count, 1);
  f.options.camera = mgsr::bench::ShellCamera(width);
  f.options.sh_degree = 3;
  f.options.distortion = false;  // as training renders it: no loss row reads the distortion
  mgsr::Rng rng(2);
  // Upstream gradients on the outputs the MGSR losses read: colour, depth and world normals.
  for (mgsr::Image* im : {&f.grad.color, &f.grad.normal_world}) {
    *im = mgsr::Image(width, width, 3);
    for (size_t i = 0; i < im->size(); ++i)
      im->data()[i] = static_cast<float>(rng.Uniform(-1, 1)) * 1e-5f;
  }
  f.grad.depth = mgsr::Image(width, width, 1);
  for (size_t i = 0; i < f.grad.depth.size(); ++i)
    f.grad.depth.data()[i] = static_cast<float>(rng.Uniform(-1, 1)) * 1e-5f;
  return f;
}

void BM_SurfelForward(benchmark::State& state) {
  const Fixture f = MakeFixture(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  omp_set_num_threads(static_cast<int>(state.range(2)));
  mgsr::SurfelRenderer renderer;
  mgsr::SurfelRender out;
  for (auto _ : state) {
    renderer.Forward(f.model, f.options, &out);
    benchmark::DoNotOptimize(out.color.data());
  }
  state.counters["tile_entries"] = static_cast<double>(renderer.bins().ids.size());
}

void BM_SurfelForwardBackward(benchmark::State& state) {
  const Fixture f = MakeFixture(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  omp_set_num_threads(static_cast<int>(state.range(2)));
  mgsr::SurfelRenderer renderer;
  mgsr::SurfelRender out;
  mgsr::SurfelGradients grads;
  for (auto _ : state) {
    renderer.Forward(f.model, f.options, &out);
    renderer.Backward(f.model, f.options, out, f.grad, &grads);
    benchmark::DoNotOptimize(grads.params.means.data());
  }
}

// The forward+backward above, timed per stage (StageCounters).
void BM_SurfelStages(benchmark::State& state) {
  const Fixture f = MakeFixture(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  omp_set_num_threads(static_cast<int>(state.range(2)));
  mgsr::bench::RunStages<mgsr::SurfelRenderer, mgsr::SurfelRender, mgsr::SurfelGradients>(state, f);
}

BENCHMARK(BM_SurfelForward)->Apply(mgsr::bench::RenderBenchmarkArgs);
BENCHMARK(BM_SurfelForwardBackward)->Apply(mgsr::bench::RenderBenchmarkArgs);
BENCHMARK(BM_SurfelStages)->Apply(mgsr::bench::StageBenchmarkArgs);
BENCHMARK(BM_SurfelForwardBackward)
    ->Name("BM_SurfelForwardBackwardRealSize")
    ->Apply(mgsr::bench::RealSizeBenchmarkArgs);
BENCHMARK(BM_SurfelStages)
    ->Name("BM_SurfelStagesRealSize")
    ->Apply(mgsr::bench::RealSizeBenchmarkArgs);

}  // namespace
