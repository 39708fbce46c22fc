#include "solvers/density_strategy.h"

namespace mgsr {

DensityStrategyRegistry& DensityStrategyRegistry::Get() {
  static DensityStrategyRegistry* registry = [] {
    auto* r = new DensityStrategyRegistry();
    RegisterBuiltinDensityStrategies(r);
    return r;
  }();
  return *registry;
}

}  // namespace mgsr
