// LossRegistry: creates loss terms by name from a JSON config, so a researcher adds a term by
// writing one class and one registration line (in builtin_losses.cc or in their own code):
//   LossRegistry::Get().Register("my_term", [](const nlohmann::json& c, Status* s) { ... });
// Config keys understood by the built-in terms: "buffer" (color, transmitted, depth, normal, ...),
// "target" / "guide" (image, transmitted), "lambda", "masked", "transmitted_weight",
// "image_weight".
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mgsr/core/named_registry.h"
#include "mgsr/core/status.h"
#include "mgsr/loss/loss_term.h"

namespace mgsr {

class LossRegistry : public NamedRegistry<LossTerm, const nlohmann::json&> {
 public:
  LossRegistry() : NamedRegistry("loss term", '\'') {}
  // The process-wide registry, with the built-in terms registered.
  static LossRegistry& Get();
};

// Registers l1, dssim, render, mutual_render, tv, normal_consistency, mutual_depth, distortion.
void RegisterBuiltinLosses(LossRegistry* registry);

// Config helpers for factories.
Status ParseBuffer(const nlohmann::json& config, const char* key, Buffer fallback, Buffer* out);

}  // namespace mgsr
