#include "solvers/primitive_prior.h"

namespace mgsr {

PriorRegistry& PriorRegistry::Get() {
  static PriorRegistry* registry = [] {
    auto* r = new PriorRegistry();
    RegisterBuiltinPriors(r);
    return r;
  }();
  return *registry;
}

void PriorRegistry::Register(const std::string& name, Factory factory) {
  factories_[name] = std::move(factory);
}

std::unique_ptr<PrimitivePrior> PriorRegistry::Create(const std::string& name,
                                                      const nlohmann::json& config,
                                                      Status* status) const {
  auto it = factories_.find(name);
  if (it == factories_.end()) {
    std::string known;
    for (const std::string& n : Names()) known += (known.empty() ? "" : ", ") + n;
    *status = Status::Error("unknown prior \"" + name + "\" (known: " + known + ")");
    return nullptr;
  }
  *status = Status::Ok();
  std::unique_ptr<PrimitivePrior> p = it->second(config, status);
  if (p == nullptr && status->ok())
    *status = Status::Error("prior \"" + name + "\" could not be created");
  if (!status->ok()) *status = status->WithContext("prior \"" + name + "\": ");
  return status->ok() ? std::move(p) : nullptr;
}

std::vector<std::string> PriorRegistry::Names() const {
  std::vector<std::string> names;
  for (const auto& [name, factory] : factories_) names.push_back(name);
  return names;
}

const ParamBlock* FindParamBlock(const std::vector<ParamBlock>& blocks, const std::string& name) {
  for (const ParamBlock& b : blocks)
    if (b.name == name) return &b;
  return nullptr;
}

Status CheckParamBlock(const std::vector<ParamBlock>& blocks, const std::string& name, int width) {
  const ParamBlock* b = FindParamBlock(blocks, name);
  if (b == nullptr) return Status::Error("the model has no parameter block \"" + name + "\"");
  if (b->width != width)
    return Status::Error("parameter block \"" + name + "\" has width " + std::to_string(b->width) +
                         ", expected " + std::to_string(width));
  return Status::Ok();
}

}  // namespace mgsr
