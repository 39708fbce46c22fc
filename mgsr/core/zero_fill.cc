#include "mgsr/core/zero_fill.h"

#include <omp.h>

#include <cstring>

namespace mgsr {

void ZeroFill(size_t n, std::vector<float>* v) {
  v->resize(n);
  float* p = v->data();
  // Below this, waking the other threads costs more than the fill.
  constexpr size_t kParallelFrom = size_t{1} << 16;
  const int threads = n >= kParallelFrom ? omp_get_max_threads() : 1;
#pragma omp parallel num_threads(threads)
  {
    const size_t t = static_cast<size_t>(omp_get_thread_num()),
                 count = static_cast<size_t>(omp_get_num_threads());
    const size_t begin = n * t / count, end = n * (t + 1) / count;
    if (end > begin) std::memset(p + begin, 0, (end - begin) * sizeof(float));
  }
}

}  // namespace mgsr
