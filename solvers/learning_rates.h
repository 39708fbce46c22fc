// Learning rates: the solver schedules them by kind of parameter (RateSchedule, one per step), and
// each primitive type maps its own parameter blocks onto those kinds (P::LearningRates, with
// FillRates), so the solver never names a block and a block no table knows is a programming error,
// not a silent rate of 0.
#pragma once

#include <string>
#include <vector>

namespace mgsr {

// The rates of one step (method.md 1.8).
struct RateSchedule {
  double position = 0;  // the position rate at this step (decayed, times the scene's extent)
  double scale = 0, rotation = 0, opacity = 0;
  double color = 0;        // SH degree 0; the higher degrees take a twentieth of it
  bool reflection = true;  // false: the reflected layer's blocks are frozen (rate 0)
  float batch_factor = 1;  // sqrt(views per step) with --batch_views and batch_sqrt_lr
};

enum class RateKind {
  kPosition,
  kScale,
  kRotation,
  kOpacity,
  kColor,             // SH coefficients: band 0 (the first 3 columns) at `color`, the rest / 20
  kReflectedOpacity,  // as kOpacity, frozen without the reflected layer
  kReflectedColor,    // as kColor, frozen without the reflected layer
};

// Fills `rates` (sized `width` by the caller) for a block of `kind` at schedule `s`.
void FillRates(RateKind kind, const RateSchedule& s, int width, std::vector<float>* rates);

// A primitive type's table: block name -> kind. Dies naming the block when it is not listed (every
// block a model offers must have a rate; a new block needs a row here).
struct BlockRate {
  const char* block;
  RateKind kind;
};
template <size_t N>
void TableRates(const BlockRate (&table)[N], const char* type, const RateSchedule& s,
                const std::string& block, int width, std::vector<float>* rates);
[[noreturn]] void UnknownRateBlock(const char* type, const std::string& block);

template <size_t N>
void TableRates(const BlockRate (&table)[N], const char* type, const RateSchedule& s,
                const std::string& block, int width, std::vector<float>* rates) {
  for (const BlockRate& row : table) {
    if (block == row.block) {
      FillRates(row.kind, s, width, rates);
      return;
    }
  }
  UnknownRateBlock(type, block);
}

}  // namespace mgsr
