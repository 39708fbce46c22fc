// Software prefetch of a primitive's SH rows a few primitives ahead, for the per-primitive loops of
// the projections. Their rows (48 floats = three cache lines per SH block) sit beside some twenty
// other per-primitive arrays the same loop streams through, more streams than the hardware
// prefetcher follows: without this, a trained 3DGS model's projection waited on every row's third
// line (`perf annotate`: the loads of the row's last cache line led the forward's SH sum).
#pragma once

#include <cstddef>

namespace mgsr {

// How many primitives ahead the projections fetch (2 did best on the trained 3DGS model and the
// 100k benchmark; 12 or more no longer helped the backward at all).
constexpr int kPrefetchAhead = 2;

// Prefetches the `count` (> 0) floats at `p` (a row), a cache line at a time, the last one too
// (a row need not start on a line).
inline void PrefetchRow(const float* p, size_t count) {
  for (size_t k = 0; k < count; k += 16) __builtin_prefetch(p + k);
  __builtin_prefetch(p + count - 1);
}

}  // namespace mgsr
