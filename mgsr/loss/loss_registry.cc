#include "mgsr/loss/loss_registry.h"

namespace mgsr {

LossRegistry& LossRegistry::Get() {
  static LossRegistry* registry = [] {
    auto* r = new LossRegistry();
    RegisterBuiltinLosses(r);
    return r;
  }();
  return *registry;
}

void LossRegistry::Register(const std::string& name, Factory factory) {
  factories_[name] = std::move(factory);
}

std::unique_ptr<LossTerm> LossRegistry::Create(const std::string& name,
                                               const nlohmann::json& config, Status* status) const {
  const auto it = factories_.find(name);
  if (it == factories_.end()) {
    std::string known;
    for (const auto& [n, f] : factories_) known += (known.empty() ? "" : ", ") + n;
    *status = Status::Error("unknown loss term '" + name + "' (known: " + known + ")");
    return nullptr;
  }
  *status = Status::Ok();
  std::unique_ptr<LossTerm> term = it->second(config, status);
  if (!status->ok()) *status = status->WithContext("loss term '" + name + "': ");
  return status->ok() ? std::move(term) : nullptr;
}

std::vector<std::string> LossRegistry::Names() const {
  std::vector<std::string> names;
  for (const auto& [n, f] : factories_) names.push_back(n);
  return names;
}

Status ParseBuffer(const nlohmann::json& config, const char* key, Buffer fallback, Buffer* out) {
  *out = fallback;
  if (!config.contains(key)) return Status::Ok();
  const std::string v = config[key].is_string() ? config[key].get<std::string>() : "";
  for (int b = 0; b < kNumBuffers; ++b) {
    if (v == BufferName(static_cast<Buffer>(b))) {
      *out = static_cast<Buffer>(b);
      return Status::Ok();
    }
  }
  return Status::Error(std::string("unknown buffer '") + v + "' for '" + key + "'");
}

}  // namespace mgsr
