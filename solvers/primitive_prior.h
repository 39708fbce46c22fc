// A loss row that reads a branch's primitives instead of a render: a prior on the parameters (for
// example that overlapping disks facing the same way lie on one sheet). It is a row of the loss
// table like a render term ("term" names a PriorRegistry entry, weight and first_iteration as any
// row's), evaluated once per step on the model, its gradient added to the batch's summed view
// gradients before Adam (scaled by the batch's view count, so its weight means what a render
// row's weight means: per view). A new prior is one class and one registration line:
//
//   PriorRegistry::Get().Register("my_prior", [](const nlohmann::json& c, Status* s) { ... });
//
// A prior keeps no state from step to step that a checkpoint would have to carry: the step's value
// and gradient are a function of the parameters alone (scratch storage may persist, to allocate
// nothing in steady steps). A prior opens its own ProfileScope (mgsr/core/profiler.h), so --profile
// shows its time by name.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mgsr/core/named_registry.h"
#include "mgsr/core/status.h"
#include "mgsr/model/param_block.h"

namespace mgsr {

class PrimitivePrior {
 public:
  virtual ~PrimitivePrior() = default;
  // OK when `params` (a model's blocks) has every block the prior reads, with the width it
  // expects; else why not (the solver names the row).
  virtual Status Check(const std::vector<ParamBlock>& params) const = 0;
  // The prior's value at `params`; with `gradients` (blocks of the same names and sizes), adds
  // scale * d value / d parameter into them.
  virtual double Evaluate(const std::vector<ParamBlock>& params, double scale,
                          const std::vector<ParamBlock>* gradients) = 0;
};

class PriorRegistry : public NamedRegistry<PrimitivePrior, const nlohmann::json&> {
 public:
  PriorRegistry() : NamedRegistry("prior", '"') {}
  // The process-wide registry, with the built-in priors registered.
  static PriorRegistry& Get();
};

// Registers "surfel_layer" (solvers/surfel_layer_prior.cc).
void RegisterBuiltinPriors(PriorRegistry* registry);

// The block named `name` of `blocks`, or null.
const ParamBlock* FindParamBlock(const std::vector<ParamBlock>& blocks, const std::string& name);
// OK when `blocks` has a block `name` of width `width`; else an error naming it.
Status CheckParamBlock(const std::vector<ParamBlock>& blocks, const std::string& name, int width);

}  // namespace mgsr
