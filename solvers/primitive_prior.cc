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
