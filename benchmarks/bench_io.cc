// BM_GaussianPlyWrite / BM_GaussianPlyRead: a whole 3DGS model with reflection (SH degree 3: 111
// float properties per Gaussian) written to and read back from a binary PLY file, as mgsr_solve
// writes its models and mgsr_render, mgsr_export and resumed runs read them. Argument: the number
// of Gaussians (a 1M-Gaussian file is 444 MB).
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstdio>
#include <string>

#include "mgsr/core/rng.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/model/gaussian_model.h"

namespace {

mgsr::GaussianModel RandomModel(size_t n) {
  mgsr::GaussianModel m;
  m.max_sh_degree = 3;
  m.Resize(n);
  mgsr::Rng rng(5);
  for (mgsr::ParamBlock& b : m.Blocks())
    for (float& v : *b.data) v = static_cast<float>(rng.Uniform(-1, 1));
  return m;
}

std::string TempPath() {
  return "/tmp/mgsr_bench_io_" + std::to_string(static_cast<long>(getpid())) + ".ply";
}

void BM_GaussianPlyWrite(benchmark::State& state) {
  const mgsr::GaussianModel m = RandomModel(static_cast<size_t>(state.range(0)));
  const std::string path = TempPath();
  for (auto _ : state) {
    if (!mgsr::WriteGaussianPly(path, m).ok()) state.SkipWithError("write failed");
  }
  std::remove(path.c_str());
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_GaussianPlyWrite)->ArgName("gaussians")->Arg(100000)->Unit(benchmark::kMillisecond);

void BM_GaussianPlyRead(benchmark::State& state) {
  const std::string path = TempPath();
  if (!mgsr::WriteGaussianPly(path, RandomModel(static_cast<size_t>(state.range(0)))).ok()) {
    state.SkipWithError("write failed");
    return;
  }
  mgsr::GaussianModel m;
  for (auto _ : state) {
    if (!mgsr::ReadGaussianPly(path, &m).ok()) state.SkipWithError("read failed");
  }
  std::remove(path.c_str());
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_GaussianPlyRead)->ArgName("gaussians")->Arg(100000)->Unit(benchmark::kMillisecond);

}  // namespace
