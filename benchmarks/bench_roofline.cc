// The machine's own ceilings, for reading the rasterizer benchmarks against (docs/performance.md,
// "The rasterizers"): how many 16-lane float operations one thread retires per second when
// nothing waits on memory, and how many bytes per second it reads from L1, L2 and main memory.
// Built with the rasterizers' instruction set (-march=native where they have it), on the same
// 16-lane vectors (mgsr/render/simd16.h).
//
//   BM_RooflineVectorFma       independent multiply-adds: the arithmetic peak (flops: 2 per lane)
//   BM_RooflineVectorMix       the forward's kinds of instruction (multiply, multiply-add,
//                              compare, blend, masked move): 16-lane instructions per second
//   BM_RooflineRead/bytes      sums of a buffer of that size, read over and over: bytes per second
#include <benchmark/benchmark.h>

#include <vector>

#include "mgsr/render/simd16.h"

namespace {

using mgsr::simd::F16;

F16 Splat(float v) {
  F16 r;
  for (int i = 0; i < 16; ++i) r[i] = v;
  return r;
}

// Twelve independent chains: enough to cover the multiply-add latency on two pipes.
void BM_RooflineVectorFma(benchmark::State& state) {
  constexpr int kChains = 12, kSteps = 1000;
  F16 acc[kChains];
  for (int k = 0; k < kChains; ++k) acc[k] = Splat(1.0f + k * 1e-3f);
  const F16 m = Splat(0.999f), a = Splat(1e-4f);
  for (auto _ : state) {
    for (int s = 0; s < kSteps; ++s) {
      for (int k = 0; k < kChains; ++k) acc[k] = acc[k] * m + a;
    }
    benchmark::DoNotOptimize(acc);
  }
  state.counters["flops"] = benchmark::Counter(2.0 * 16 * kChains * kSteps * state.iterations(),
                                               benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RooflineVectorFma);

// Per chain and step seven 16-lane instructions of the kinds a forward row is made of (GCC 12,
// AVX-512: a multiply; the min as a compare and a blend; an accumulation's multiply-add; the
// termination test's compare; the transmittance's negative multiply-add and its masked move):
// what a row's arithmetic can retire at best when it has enough independent work.
void BM_RooflineVectorMix(benchmark::State& state) {
  constexpr int kChains = 8, kSteps = 1000;
  F16 t[kChains], c[kChains];
  for (int k = 0; k < kChains; ++k) {
    t[k] = Splat(1.0f - k * 1e-3f);
    c[k] = Splat(0);
  }
  const F16 alpha = Splat(0.01f), color = Splat(0.5f), cap = Splat(0.99f), floor = Splat(1e-4f);
  for (auto _ : state) {
    for (int s = 0; s < kSteps; ++s) {
      for (int k = 0; k < kChains; ++k) {
        const F16 a = mgsr::simd::Min(alpha * t[k], cap);
        c[k] = c[k] + a * color;
        t[k] = mgsr::simd::IfElse(t[k] > floor, t[k] - a * t[k], t[k]);
      }
    }
    benchmark::DoNotOptimize(t);
    benchmark::DoNotOptimize(c);
  }
  state.counters["vector_ops"] =
      benchmark::Counter(7.0 * kChains * kSteps * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RooflineVectorMix);

void BM_RooflineRead(benchmark::State& state) {
  const size_t floats = static_cast<size_t>(state.range(0)) / sizeof(float);
  std::vector<F16> data(floats / 16, Splat(1.0f));
  for (auto _ : state) {
    F16 s0 = Splat(0), s1 = Splat(0), s2 = Splat(0), s3 = Splat(0);
    for (size_t i = 0; i + 3 < data.size(); i += 4) {
      s0 = s0 + data[i];
      s1 = s1 + data[i + 1];
      s2 = s2 + data[i + 2];
      s3 = s3 + data[i + 3];
    }
    F16 s = s0 + s1 + s2 + s3;
    benchmark::DoNotOptimize(s);
  }
  state.counters["bytes"] = benchmark::Counter(
      static_cast<double>(state.range(0)) * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_RooflineRead)->Arg(16 << 10)->Arg(512 << 10)->Arg(256 << 20);

}  // namespace
