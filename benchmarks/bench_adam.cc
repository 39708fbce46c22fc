// BM_AdamStep: one Adam update of a whole 3DGS model (means, scales, rotations, opacities, SH and
// reflected SH of degree 3, beta), the optimiser step every training iteration ends with.
// BM_AdamStepIdleRows: the same after one step with gradients everywhere and 1,000 in which 90% of
// the rows had zero gradient (what primitives the views do not see get), the state where the
// moments of a naive Adam turn subnormal. Argument: the number of Gaussians. SH bands get their own
// rate (as in training).
#include <benchmark/benchmark.h>

#include <algorithm>

#include "mgsr/core/rng.h"
#include "mgsr/model/gaussian_model.h"
#include "solvers/adam.h"

namespace {

struct AdamFixture {
  mgsr::GaussianModel model, grads;
  std::vector<mgsr::ParamBlock> params, gradients;
  mgsr::Adam adam;
  int64_t entries = 0;
  // Rows from `idle_from` on get zero gradients.
  AdamFixture(size_t n, size_t idle_from) {
    model.max_sh_degree = grads.max_sh_degree = 3;
    model.Resize(n);
    grads.Resize(n);
    mgsr::Rng rng(3);
    for (mgsr::ParamBlock& b : grads.Blocks()) {
      const size_t active = idle_from * b.width;
      for (size_t i = 0; i < b.data->size(); ++i)
        (*b.data)[i] = i < active ? static_cast<float>(rng.Normal()) * 1e-3f : 0.0f;
    }
    params = model.Blocks();
    gradients = grads.Blocks();
    for (const mgsr::ParamBlock& b : params) entries += static_cast<int64_t>(b.data->size());
  }
  std::string Step() { return adam.Step(params, gradients, Rates); }
  static void Rates(const std::string& name, int width, std::vector<float>* r) {
    const bool sh = name == "sh" || name == "ref_sh";
    for (int c = 0; c < width; ++c) (*r)[c] = sh && c >= 3 ? 1.25e-4f : 2.5e-3f;
  }
};

void BM_AdamStep(benchmark::State& state) {
  const size_t n = static_cast<size_t>(state.range(0));
  AdamFixture f(n, n);
  for (auto _ : state) benchmark::DoNotOptimize(f.Step());
  state.SetItemsProcessed(state.iterations() * f.entries);
}

void BM_AdamStepIdleRows(benchmark::State& state) {
  const size_t n = static_cast<size_t>(state.range(0));
  AdamFixture f(n, n);
  f.Step();  // every row once with a gradient, then 90% of them idle
  for (mgsr::ParamBlock& b : f.grads.Blocks())
    std::fill(b.data->begin() + (n / 10) * b.width, b.data->end(), 0.0f);
  for (int i = 0; i < 1000; ++i) f.Step();
  for (auto _ : state) benchmark::DoNotOptimize(f.Step());
  state.SetItemsProcessed(state.iterations() * f.entries);
}

BENCHMARK(BM_AdamStep)
    ->Arg(25000)
    ->Arg(100000)
    ->ArgName("gaussians")
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AdamStepIdleRows)
    ->Arg(25000)
    ->ArgName("gaussians")
    ->Unit(benchmark::kMillisecond)
    ->Iterations(20);

}  // namespace
