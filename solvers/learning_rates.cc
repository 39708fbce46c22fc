#include "solvers/learning_rates.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>

namespace mgsr {

void FillRates(RateKind kind, const RateSchedule& s, int width, std::vector<float>* rates) {
  const bool reflected = kind == RateKind::kReflectedOpacity || kind == RateKind::kReflectedColor;
  if (reflected && !s.reflection) {
    std::fill(rates->begin(), rates->end(), 0.0f);
    return;
  }
  const float f = s.batch_factor;
  if (kind == RateKind::kColor || kind == RateKind::kReflectedColor) {
    // Band 0 (the first 3 columns) at the colour rate, higher bands at 1/20 of it.
    for (int k = 0; k < width; ++k)
      (*rates)[k] = static_cast<float>(k < 3 ? s.color : s.color / 20);
  } else {
    double r = 0;
    switch (kind) {
      case RateKind::kPosition:
        r = s.position;
        break;
      case RateKind::kScale:
        r = s.scale;
        break;
      case RateKind::kRotation:
        r = s.rotation;
        break;
      default:
        r = s.opacity;
        break;
    }
    std::fill(rates->begin(), rates->end(), static_cast<float>(r));
  }
  if (f != 1.0f) {
    for (float& r : *rates) r *= f;
  }
}

void UnknownRateBlock(const char* type, const std::string& block) {
  std::fprintf(stderr, "internal error: %s has no learning rate for parameter block '%s'\n", type,
               block.c_str());
  std::abort();
}

}  // namespace mgsr
