// When the loss kernels use every thread.
#pragma once

#include <cstdint>

namespace mgsr {

// Per-pixel loss kernels run on all threads from this many pixels (a 128 px view) on; below it,
// starting the threads costs more than they save (BM_Dssim/width:128: one thread 0.25 ms for
// three planes, two 0.15 ms).
constexpr int64_t kParallelPixels = 16384;

}  // namespace mgsr
