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
