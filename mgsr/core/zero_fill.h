// Zero-filling the large float arrays of a training step (the gradient buffers) on all threads.
#pragma once

#include <cstddef>
#include <vector>

namespace mgsr {

// Makes `v` hold `n` zeros, the fill split over the OpenMP threads. The gradients of 25k
// Gaussians (SH degree 3, a reflected colour) are 10 MB: filled by one thread at every step, they
// kept the other cores waiting (std::vector::assign is serial). Growing the storage still zeroes
// the new part serially (only when the model has grown).
void ZeroFill(size_t n, std::vector<float>* v);

}  // namespace mgsr
