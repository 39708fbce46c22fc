#include "solvers/primitive_rows.h"

#include <algorithm>

#include "mgsr/model/activations.h"

namespace mgsr {

size_t PrimitiveRows::size() const {
  return blocks_.empty() || blocks_[0].width == 0 ? 0 : blocks_[0].data->size() / blocks_[0].width;
}

float* PrimitiveRows::Block(const std::string& name) const {
  for (const ParamBlock& b : blocks_)
    if (b.name == name) return b.data->data();
  return nullptr;
}

int PrimitiveRows::Width(const std::string& name) const {
  for (const ParamBlock& b : blocks_)
    if (b.name == name) return b.width;
  return 0;
}

void PrimitiveRows::AppendCopies(const std::vector<int>& rows) {
  if (rows.empty()) return;
  AppendRowsFrom(blocks_, blocks_, rows);
  adam_->AppendZeroRows(rows.size());
}

void PrimitiveRows::KeepRows(const std::vector<uint8_t>& keep) {
  mgsr::KeepRows(blocks_, keep);
  adam_->KeepRows(keep);
}

void PrimitiveRows::ZeroMoments(const std::vector<int>& rows) { adam_->ZeroRows(rows); }

void PrimitiveRows::CopyRow(size_t from, size_t to) {
  for (const ParamBlock& b : blocks_) {
    float* d = b.data->data();
    std::copy(d + from * b.width, d + (from + 1) * b.width, d + to * b.width);
  }
}

void PrimitiveRows::ResetOpacity() {
  const size_t n = size();
  for (const auto& [name, cap] : layout_->opacity_reset_caps) {
    float* logits = Block(name);
    if (logits == nullptr) continue;
    const float max_logit = InverseSigmoid(cap);
    for (size_t i = 0; i < n; ++i) logits[i] = std::min(logits[i], max_logit);
    adam_->ResetBlock(name);
  }
}

}  // namespace mgsr
