// PrimitiveRows: one branch's model and optimiser state as density control edits them, whatever
// the primitive type: parameter blocks by name, the type's layout (scale axes, opacity blocks,
// what an opacity reset caps), and row operations that move the optimiser state with the rows.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "mgsr/model/param_block.h"
#include "solvers/adam.h"

namespace mgsr {

// What a primitive type tells density control about its rows.
struct PrimitiveLayout {
  int scale_axes = 3;  // columns of "log_scales": 3 for Gaussians, 2 for flat surfels
  // Sigmoid logits of opacity, the primitive's own first ("opacity_logits"); further ones (the 3DGS
  // reflected opacity) are blended by their own chain and follow the primitive's opacity decisions.
  std::vector<std::string> opacity_blocks = {"opacity_logits"};
  // The reference's opacity reset: each block's activation capped at the value (moments zeroed).
  std::vector<std::pair<std::string, float>> opacity_reset_caps = {{"opacity_logits", 0.01f}};
};

// One branch's model and optimiser state as a strategy edits them. Valid while the model lives;
// Block() pointers are invalidated by the row operations (ask again after one).
class PrimitiveRows {
 public:
  PrimitiveRows(std::vector<ParamBlock> blocks, Adam* adam, const PrimitiveLayout* layout)
      : blocks_(std::move(blocks)), adam_(adam), layout_(layout) {}

  size_t size() const;
  const PrimitiveLayout& layout() const { return *layout_; }
  const std::vector<ParamBlock>& blocks() const { return blocks_; }
  // Row-major data of a block, nullptr when the model has none of that name.
  float* Block(const std::string& name) const;
  int Width(const std::string& name) const;  // 0 when absent

  // Row operations on every block and the optimiser state together.
  void AppendCopies(const std::vector<int>& rows);  // new rows start with zero moments
  void KeepRows(const std::vector<uint8_t>& keep);
  void ZeroMoments(const std::vector<int>& rows);  // of every block
  // Row `to` takes row `from`'s values in every block (moments unchanged).
  void CopyRow(size_t from, size_t to);
  // The reference's opacity reset (layout().opacity_reset_caps).
  void ResetOpacity();

 private:
  std::vector<ParamBlock> blocks_;
  Adam* adam_;
  const PrimitiveLayout* layout_;
};

}  // namespace mgsr
