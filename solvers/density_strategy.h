// DensityStrategy: how a branch decides how many primitives it has and where (clone, split,
// prune, relocate, add). A branch trainer owns one; the solver picks it by name
// (`--density reference|mcmc`) from DensityStrategyRegistry, so a new strategy is one class and
// one registration line (RegisterBuiltinDensityStrategies, or the researcher's own code):
//   DensityStrategyRegistry::Get().Register("mine", [](const DensityContext& c,
//       const nlohmann::json& config, Status* s) { return std::make_unique<Mine>(c); });
//
// A strategy sees a branch's model through PrimitiveRows: its parameter blocks by name (means,
// log_scales, quats, opacity logits, ...), the primitive type's layout (how many scale axes, which
// blocks are opacities, what an opacity reset caps), and row operations that move the optimiser
// state with the rows. It never names a primitive type, so one strategy serves both branches.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/named_registry.h"
#include "mgsr/core/rng.h"
#include "mgsr/core/status.h"
#include "mgsr/io/binary_stream.h"
#include "solvers/adam.h"
#include "solvers/density_control.h"
#include "solvers/primitive_rows.h"
#include "solvers/solver_options.h"

namespace mgsr {

// What a strategy knows of its branch and run (fixed for the run).
struct DensityContext {
  BranchSchedule schedule;  // when density control runs, and the reference's prune threshold
  DensityOptions density;   // thresholds of the reference strategy and the budget
  double extent = 1;        // the scene's extent
};

// One view of a training step, as a strategy's per-view statistics see it.
struct DensityView {
  int iteration = 0;
  const Camera* camera = nullptr;
  const std::vector<float>* mean2d = nullptr;  // d loss / d screen mean, 2 per primitive
  const std::vector<float>* radii = nullptr;   // > 0 where the primitive was drawn
};

// One training step as density control sees it: a step trains on a batch of `views` views
// (--batch_views; 1 by default), whose per-view statistics arrive summed.
struct DensityStep {
  int iteration = 0;
  int views = 1;
  // The sum over the batch's views of ViewStatistics (ViewStatisticsWidth floats per primitive,
  // primitive-major), or null when the width is 0 at this iteration.
  const std::vector<float>* statistics = nullptr;
  float position_lr = 0;  // the means' learning rate at this step
};

class DensityStrategy {
 public:
  virtual ~DensityStrategy() = default;

  // Once, on the initial model (before the first step; not on a resume).
  virtual void Begin(PrimitiveRows* /*rows*/, Rng* /*rng*/) {}

  // Statistics a strategy gathers per view (e.g. screen-gradient norms): ViewStatistics fills
  // `width` floats per primitive for one view, and the trainer sums them over the views of a batch
  // (in a fixed order, also across processes: solvers/view_group.h) before BeforeStep sees them.
  // Statistics that are sums over views therefore come out the same however a batch is split.
  // The width may depend on the iteration only (every process must agree on it); 0: none.
  virtual int ViewStatisticsWidth(int /*iteration*/) const { return 0; }
  virtual void ViewStatistics(const DensityView& /*view*/, float* /*out*/) {}

  // After the backward pass, before the optimiser step: the step's statistics, and the gradient
  // of the strategy's own regulariser added into `gradients` (blocks of the same names as the
  // model's; the sum of the batch's view gradients). Returns that regulariser's value (0 when it
  // has none).
  virtual double BeforeStep(const DensityStep& step, const PrimitiveRows& rows,
                            const std::vector<ParamBlock>& gradients) = 0;
  // After the optimiser step: row operations on the strategy's schedule.
  virtual DensifyResult AfterStep(const DensityStep& step, PrimitiveRows* rows, Rng* rng) = 0;

  // Checkpoints: the strategy's state between steps. Read keeps what it read aside; CommitRead
  // installs it.
  virtual void Save(BinaryWriter* w) const = 0;
  virtual Status Read(BinaryReader* r) = 0;
  virtual void CommitRead() = 0;
};

class DensityStrategyRegistry
    : public NamedRegistry<DensityStrategy, const DensityContext&, const nlohmann::json&> {
 public:
  DensityStrategyRegistry() : NamedRegistry("density strategy", '"') {}
  // The process-wide registry, with the built-in strategies registered.
  static DensityStrategyRegistry& Get();
};

// Registers "reference" (solvers/density_reference.cc) and "mcmc" (solvers/density_mcmc.cc).
void RegisterBuiltinDensityStrategies(DensityStrategyRegistry* registry);

}  // namespace mgsr
