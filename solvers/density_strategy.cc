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

void DensityStrategyRegistry::Register(const std::string& name, Factory factory) {
  factories_[name] = std::move(factory);
}

std::unique_ptr<DensityStrategy> DensityStrategyRegistry::Create(const std::string& name,
                                                                 const DensityContext& context,
                                                                 const nlohmann::json& config,
                                                                 Status* status) const {
  auto it = factories_.find(name);
  if (it == factories_.end()) {
    std::string known;
    for (const std::string& n : Names()) known += (known.empty() ? "" : ", ") + n;
    *status = Status::Error("unknown density strategy \"" + name + "\" (known: " + known + ")");
    return nullptr;
  }
  *status = Status::Ok();
  std::unique_ptr<DensityStrategy> s = it->second(context, config, status);
  if (s == nullptr && status->ok())
    *status = Status::Error("density strategy \"" + name + "\" could not be created");
  if (!status->ok()) *status = status->WithContext("density strategy \"" + name + "\": ");
  return status->ok() ? std::move(s) : nullptr;
}

std::vector<std::string> DensityStrategyRegistry::Names() const {
  std::vector<std::string> names;
  for (const auto& [name, factory] : factories_) names.push_back(name);
  return names;
}

}  // namespace mgsr
