// BM_GaussianForward / BM_GaussianForwardBackward (BM_GaussianStages: the latter per stage): the
// 3DGS-branch render on an object-like scene (a shell of radius 1 seen from distance 3, scales
// matched to the point spacing, SH degree 3, reflection on). Arguments: image width (square
// images), Gaussian count, threads.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cmath>

#include "mgsr/core/rng.h"
#include "mgsr/render/gaussian_renderer.h"
#include "shell_scene.h"

namespace {

struct Fixture {
  mgsr::GaussianModel model;
  mgsr::GaussianRenderOptions options;
  mgsr::GaussianRenderGrad grad;
};

Fixture MakeFixture(int width, int count) {
  Fixture f;
  f.model = mgsr::bench::ShellGaussians(count, 1);
  f.options.camera = mgsr::bench::ShellCamera(width);
  f.options.sh_degree = 3;
  f.options.reflection = true;
  f.grad.color = mgsr::Image(width, width, 3);
  mgsr::Rng rng(2);
  for (size_t i = 0; i < f.grad.color.size(); ++i)
    f.grad.color.data()[i] = static_cast<float>(rng.Uniform(-1, 1)) * 1e-5f;
  return f;
}

void BM_GaussianForward(benchmark::State& state) {
  const Fixture f = MakeFixture(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  omp_set_num_threads(static_cast<int>(state.range(2)));
  mgsr::GaussianRenderer renderer;
  mgsr::GaussianRender out;
  for (auto _ : state) {
    renderer.Forward(f.model, f.options, &out);
    benchmark::DoNotOptimize(out.color.data());
  }
  state.counters["tile_entries"] = static_cast<double>(renderer.bins().ids.size());
}

void BM_GaussianForwardBackward(benchmark::State& state) {
  const Fixture f = MakeFixture(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  omp_set_num_threads(static_cast<int>(state.range(2)));
  mgsr::GaussianRenderer renderer;
  mgsr::GaussianRender out;
  mgsr::GaussianGradients grads;
  for (auto _ : state) {
    renderer.Forward(f.model, f.options, &out);
    renderer.Backward(f.model, f.options, out, f.grad, &grads);
    benchmark::DoNotOptimize(grads.params.means.data());
  }
}

// The forward+backward above, timed per stage (StageCounters).
void BM_GaussianStages(benchmark::State& state) {
  const Fixture f = MakeFixture(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  omp_set_num_threads(static_cast<int>(state.range(2)));
  mgsr::bench::RunStages<mgsr::GaussianRenderer, mgsr::GaussianRender, mgsr::GaussianGradients>(
      state, f);
}

BENCHMARK(BM_GaussianForward)->Apply(mgsr::bench::RenderBenchmarkArgs);
BENCHMARK(BM_GaussianForwardBackward)->Apply(mgsr::bench::RenderBenchmarkArgs);
BENCHMARK(BM_GaussianStages)->Apply(mgsr::bench::StageBenchmarkArgs);
BENCHMARK(BM_GaussianForwardBackward)
    ->Name("BM_GaussianForwardBackwardRealSize")
    ->Apply(mgsr::bench::RealSizeBenchmarkArgs);
BENCHMARK(BM_GaussianStages)
    ->Name("BM_GaussianStagesRealSize")
    ->Apply(mgsr::bench::RealSizeBenchmarkArgs);

}  // namespace
