// Micro-benchmarks of the synthetic-scene renderer (the ground-truth generator): BVH build and one
// view, so generator changes that slow CI down show up.
#include <benchmark/benchmark.h>

#include "mgsr/synth/ray_caster.h"
#include "mgsr/synth/shapes.h"
#include "mgsr/synth/synthetic_scene.h"

namespace {

void BM_RayCasterBuild(benchmark::State& state) {
  mgsr::TriangleMesh mesh;
  mgsr::MakeShape("dented", static_cast<int>(state.range(0)), &mesh);
  for (auto _ : state) {
    mgsr::RayCaster caster(mesh);
    benchmark::DoNotOptimize(&caster);
  }
  state.counters["triangles"] = static_cast<double>(mesh.triangles.size());
}
BENCHMARK(BM_RayCasterBuild)->Arg(0)->Arg(2)->Unit(benchmark::kMillisecond);

void BM_SyntheticView(benchmark::State& state) {
  mgsr::SynthOptions o;
  o.shape = "dented";
  o.width = o.height = static_cast<int>(state.range(0));
  o.num_views = 3;
  mgsr::SyntheticScene scene;
  if (!mgsr::MakeSyntheticScene(o, &scene).ok()) state.SkipWithError("scene");
  const mgsr::SyntheticRenderer renderer(scene, o);
  mgsr::Image rgba, depth, normal;
  for (auto _ : state) renderer.Render(scene.cameras[0], scene.lights[0], &rgba, &depth, &normal);
}
BENCHMARK(BM_SyntheticView)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond);

}  // namespace
