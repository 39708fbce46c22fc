// BM_EnvironmentRenderBackward: the learnt background of scene captures (a 64 x 32 map) rendered
// behind a view and its gradient taken, as one training step does per branch; the view changes
// every step, so the per-pixel viewing directions are recomputed each time. Arguments: image
// width (square images; 1440 has the pixels of 1920 x 1080), threads.
#include <benchmark/benchmark.h>
#include <omp.h>

#include "mgsr/core/rng.h"
#include "mgsr/model/environment_map.h"
#include "shell_scene.h"

namespace {

void BM_EnvironmentRenderBackward(benchmark::State& state) {
  const int width = static_cast<int>(state.range(0));
  omp_set_num_threads(static_cast<int>(state.range(1)));
  mgsr::EnvironmentMap map;
  map.Reset(64, 32, 0.5f);
  mgsr::Rng rng(4);
  for (float& v : map.texels) v = static_cast<float>(rng.Uniform(0, 1));
  // Two views a few degrees apart, taken in turn.
  mgsr::Camera cameras[2] = {mgsr::bench::ShellCamera(width), mgsr::bench::ShellCamera(width)};
  cameras[1].R = cameras[1].R * Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY()).toRotationMatrix();
  mgsr::Image grad(width, width, 3);
  for (size_t i = 0; i < grad.size(); ++i) grad.data()[i] = static_cast<float>(rng.Uniform(-1, 1));
  mgsr::EnvironmentRenderer renderer;
  mgsr::Image out;
  std::vector<float> d_texels;
  int k = 0;
  for (auto _ : state) {
    renderer.Render(map, cameras[k], &out);
    d_texels.assign(map.texels.size(), 0.0f);
    renderer.Backward(map, cameras[k], grad, &d_texels);
    benchmark::DoNotOptimize(d_texels.data());
    k ^= 1;
  }
}
BENCHMARK(BM_EnvironmentRenderBackward)
    ->ArgsProduct({{256, 1440}, {1, 2}})
    ->ArgNames({"width", "threads"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
