// Adam per parameter block (method.md 1.8: betas 0.9 / 0.999, eps 1e-15), with the optimiser state
// following the model's rows through density control (new rows start with zero moments).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "mgsr/model/param_block.h"

namespace mgsr {

class Adam {
 public:
  struct BlockState {
    std::vector<float> m, v;
    int width = 0;
    int64_t step = 0;
  };

  // Per-column learning rates of a block (size = block width; all 0 = frozen). Columns allow
  // different rates inside one block, e.g. SH band 0 and the higher bands.
  using LearningRates =
      std::function<void(const std::string& name, int width, std::vector<float>* rates)>;

  // One update of every block. Returns the name of the first block whose gradient holds a NaN or
  // an infinity ("" when all are finite): the caller stops, since that block's parameters and
  // moments are no longer finite either.
  std::string Step(const std::vector<ParamBlock>& params, const std::vector<ParamBlock>& grads,
                   const LearningRates& learning_rates);
  // Mirror the model's row operations.
  void KeepRows(const std::vector<uint8_t>& keep);
  void AppendZeroRows(size_t count);
  // Zeroes the moments of one block (the reference does this on opacity resets).
  void ResetBlock(const std::string& name);
  // Zeroes the moments of some rows in every block (relocated primitives start afresh).
  void ZeroRows(const std::vector<int>& rows);

  std::map<std::string, BlockState>& state() { return state_; }
  const std::map<std::string, BlockState>& state() const { return state_; }

  double beta1 = 0.9, beta2 = 0.999, eps = 1e-15;

 private:
  std::map<std::string, BlockState> state_;
  std::vector<float> rates_;  // Step's scratch (no allocation once sized)
};

}  // namespace mgsr
