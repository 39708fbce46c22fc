// ParamBlock: a named view of one parameter tensor of a model (N rows of `width` floats). Models
// list their blocks, and everything that treats parameters generically (row operations for density
// control, the optimiser's state, checkpoints) walks that list instead of naming fields.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace mgsr {

struct ParamBlock {
  std::string name;
  std::vector<float>* data;
  int width;  // floats per row
};

// Keeps rows whose keep[i] is true, in order, in every block.
void KeepRows(const std::vector<ParamBlock>& blocks, const std::vector<uint8_t>& keep);

// Appends rows `indices` of the source blocks (same names and widths, e.g. the same model) to
// the destination blocks. Safe when source and destination are the same model.
void AppendRowsFrom(const std::vector<ParamBlock>& dst, const std::vector<ParamBlock>& src,
                    const std::vector<int>& indices);

}  // namespace mgsr
