// BM_SurfelLayerPrior: one step of the surfel layer prior (solvers/surfel_layer_prior.h) on a 2DGS
// model: the neighbour search on its grid, the pair weights, the energy and its gradient into the
// means and quaternions. The disks lie on a unit sphere (Fibonacci points, each as wide as the gap
// between them), with a tenth of them doubled a third of a disk above: a sheet with some layer.
// Argument: the number of disks. Counters: disks per second.
#include <benchmark/benchmark.h>

#include <cmath>

#include "mgsr/model/activations.h"
#include "mgsr/model/surfel_model.h"
#include "solvers/surfel_layer_prior.h"

namespace {

mgsr::SurfelModel SphereWithLayer(size_t n) {
  mgsr::SurfelModel m;
  m.max_sh_degree = 0;
  m.Resize(n);
  const double golden = M_PI * (3 - std::sqrt(5.0)), scale = 2.0 / std::sqrt(0.9 * n);
  const size_t sheet = n - n / 10;
  for (size_t i = 0; i < n; ++i) {
    const size_t k = i < sheet ? i : (i - sheet) * 9;
    const double z = 1 - 2 * (k + 0.5) / sheet, r = std::sqrt(1 - z * z), a = golden * k;
    const double lift = i < sheet ? 1.0 : 1.0 + scale / 3;
    const double n3[3] = {r * std::cos(a), r * std::sin(a), z};
    for (int c = 0; c < 3; ++c) m.means[3 * i + c] = static_cast<float>(lift * n3[c]);
    // The quaternion turning +z onto the normal.
    double w = 1 + n3[2], x = -n3[1], y = n3[0];
    if (w < 1e-9) w = 0, x = 1, y = 0;
    const double len = std::sqrt(w * w + x * x + y * y);
    m.quats[4 * i] = static_cast<float>(w / len);
    m.quats[4 * i + 1] = static_cast<float>(x / len);
    m.quats[4 * i + 2] = static_cast<float>(y / len);
    m.quats[4 * i + 3] = 0;
    m.log_scales[2 * i] = m.log_scales[2 * i + 1] = static_cast<float>(std::log(scale));
    m.opacity_logits[i] = mgsr::InverseSigmoid(0.8f);
  }
  return m;
}

void BM_SurfelLayerPrior(benchmark::State& state) {
  mgsr::SurfelModel model = SphereWithLayer(static_cast<size_t>(state.range(0)));
  mgsr::SurfelModel grads = model;
  const std::vector<mgsr::ParamBlock> params = model.Blocks(), gradients = grads.Blocks();
  mgsr::SurfelLayerPrior prior{mgsr::SurfelLayerOptions()};
  for (auto _ : state) benchmark::DoNotOptimize(prior.Evaluate(params, 1.0, &gradients));
  state.counters["disks_per_s"] = benchmark::Counter(
      static_cast<double>(state.iterations() * state.range(0)), benchmark::Counter::kIsRate);
}

}  // namespace

BENCHMARK(BM_SurfelLayerPrior)
    ->ArgName("disks")
    ->Arg(20000)
    ->Arg(100000)
    ->Unit(benchmark::kMillisecond);
