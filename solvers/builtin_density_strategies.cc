// The built-in density strategies; a new one is one class and one line here (or a Register call
// in the researcher's own code).
#include "solvers/density_mcmc.h"
#include "solvers/density_reference.h"
#include "solvers/density_strategy.h"

namespace mgsr {

void RegisterBuiltinDensityStrategies(DensityStrategyRegistry* r) {
  r->Register("reference",
              [](const DensityContext& c, const nlohmann::json& config,
                 Status* s) -> std::unique_ptr<DensityStrategy> {
                if (!config.is_null() && !config.empty()) {
                  *s = Status::Error("takes no config (its thresholds are solver options)");
                  return nullptr;
                }
                return std::make_unique<ReferenceDensity>(c);
              });
  r->Register("mcmc",
              [](const DensityContext& c, const nlohmann::json& config,
                 Status* s) -> std::unique_ptr<DensityStrategy> {
                if (c.density.max_primitives == 0) {
                  *s =
                      Status::Error("needs a budget (--max_gaussians / --max_surfels or --budget)");
                  return nullptr;
                }
                McmcOptions o;
                *s = McmcOptions::FromJson(config, &o);
                if (!s->ok()) return nullptr;
                return std::make_unique<McmcDensity>(c, o);
              });
}

}  // namespace mgsr
