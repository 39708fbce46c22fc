// The reference's density control of both branches (method.md 1.10), the "reference" density
// strategy: view-averaged screen-gradient statistics, clone (small primitives) and split (large
// ones, two children scaled by 1/1.6 sampled from the primitive's own Gaussian), pruning by opacity
// and world size, opacity resets (3DGS: also the reflected opacity, and beta capped at 0.1), and a
// primitive budget so a model never grows past what the user allows. The optimiser state follows
// every row operation.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mgsr/core/rng.h"
#include "mgsr/io/scene.h"
#include "solvers/primitive_rows.h"

namespace mgsr {

struct DensityOptions {
  float grad_threshold = 2e-4f;  // on the NDC screen-gradient norm
  float percent_dense = 0.01f;   // clone below, split above this share of the scene extent
  float min_opacity = 0.005f;    // prune below (3DGS 0.005, 2DGS 0.05)
  float max_world_size =
      0.1f;                   // prune larger than this share of the extent (after the first reset)
  size_t max_primitives = 0;  // 0 = no budget
};

// Per-primitive accumulators between density-control steps.
struct DensityStats {
  std::vector<float> grad_sum, count;

  void Reset(size_t n) {
    grad_sum.assign(n, 0.0f);
    count.assign(n, 0.0f);
  }
  // Adds the views of a step: per primitive, the sum over the views of its NDC screen-gradient
  // norm where drawn and the number of views it was drawn in (ReferenceDensity::ViewStatistics).
  void AccumulateViews(const std::vector<float>& sums) {
    const size_t n = std::min(grad_sum.size(), sums.size() / 2);
    for (size_t i = 0; i < n; ++i) {
      grad_sum[i] += sums[2 * i];
      count[i] += sums[2 * i + 1];
    }
  }
};

// What one density-control event did (a strategy fills the fields it uses).
struct DensifyResult {
  size_t cloned = 0, split = 0, pruned = 0;
  size_t relocated = 0, added = 0;  // MCMC: dead primitives moved, new ones sampled
};

// One densify-and-prune step; `prune_large` enables the world-size test. Resets `stats`.
DensifyResult DensifyAndPrune(PrimitiveRows* rows, DensityStats* stats,
                              const DensityOptions& options, double extent, bool prune_large,
                              Rng* rng);

// The budget a branch gets when the user gives none: kBudgetPerPixel primitives per pixel of the
// largest training view, and at least kMinBudget. Far above what an object needs but a bound, so
// a run whose density control runs away (cameras far from the object grew the model 12x in 1,100
// iterations, to 1 GB) stops growing instead of exhausting memory. Measured counts per pixel vary
// with the resolution: 0.3-0.8 for 256 px objects (12,000-50,000 primitives), up to 13.6 at 64 px
// (55,833 Gaussians in the benchmark suite), hence the floor.
constexpr size_t kBudgetPerPixel = 4;
constexpr size_t kMinBudget = 500000;
size_t DefaultPrimitiveBudget(const Scene& scene);

// `--budget auto`: a budget from what the training views show. A branch gets its rate x the
// square root of F, the median over training views of the foreground pixels in a view (the mask,
// else the alpha, else every pixel): a count proportional to the object's size in pixels, not to
// its area. Why not the area: flat primitives that follow a surface of curvature radius R to
// within a fixed part of a pixel footprint f can be at most ~sqrt(R f) across, so a surface of
// area A needs ~A / (R f) of them, which for one shape (A / R^2 fixed) grows as R / f, i.e. as
// sqrt(F). Measured (BENCHMARKS.md, quality against model size): suzanne at 256 px (F 12,271)
// keeps its NC and PSNR from ~15,000 surfels and ~20,000 Gaussians, the 64 px torus (F 1,114)
// from ~5,000 of each: 2.5x the count for 11x the pixels. A quarter of the Gaussians (45) was
// tried: within the run-to-run spread on NC and CD of eight masked scenes and 1.4x faster, but
// the harness's constant-light scene lost 1.6 dB of aligned PSNR (control 31.10 -> 29.48) and the
// unmasked one 4.6 NC points (BENCHMARKS.md, "Quality against model size"). At least
// kMinAutoBudget. `why` says how, for the log and metrics.json.
constexpr double kAutoGaussiansPerSqrtPixel = 180;
constexpr double kAutoSurfelsPerSqrtPixel = 135;
constexpr size_t kMinAutoBudget = 1000;
struct SceneBudget {
  size_t gaussians = 0, surfels = 0;
  double foreground_pixels = 0;  // the median per training view
  std::string why;
};
SceneBudget AutoPrimitiveBudget(const Scene& scene);

}  // namespace mgsr
