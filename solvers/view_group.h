// ViewGroup: the processes that share each batch of training views (--batch_views). One process
// alone is the LocalViewGroup (nothing to exchange); under `mpirun` it is an MpiViewGroup
// (solvers/mpi_view_group.h, built with -DMGSR_WITH_MPI=ON). Rank r of R takes the r-th of R equal,
// contiguous parts of every batch.
//
// Why a fixed tree: a batch's gradient is the sum of its views' gradients, and float addition is
// not associative, so "the same sum" needs one order wherever it is computed. The order is
// recursive halving over the batch's positions (BatchTreeSum): sum(lo, hi) = sum(lo, mid) +
// sum(mid, hi), mid = lo + (hi - lo) / 2. With R a power of two dividing B, every rank's part is a
// subtree, and SumTree combines the parts by recursive doubling (at level l, rank r adds its
// partner r ^ 2^l's value; float addition is commutative, so both hold the same bits), which
// forms exactly the tree's upper levels: R processes end with the bits one process computes.
#pragma once

#include <cstddef>
#include <string>

#include "mgsr/core/status.h"

namespace mgsr {

class ViewGroup {
 public:
  virtual ~ViewGroup() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  // Sums `n` floats (each process: the sum over its part of the batch) over the processes in the
  // order of the batch tree; every process ends with the same values.
  virtual Status SumTree(float* data, size_t n) = 0;
  // Sums doubles where at most one process holds a non-zero value per entry (per-position values
  // of a batch: each position belongs to one process), so the order does not matter.
  virtual Status SumDisjoint(double* data, size_t n) = 0;
  // The largest of the processes' values into *value (decisions every process must share: stop,
  // abort).
  virtual Status Max(int* value) = 0;
  // Point to point, for work that process 0 takes in an order of its own (the mesh's depth
  // frames): `n` floats to / from process `peer`. Blocking; the sizes must match.
  virtual Status Send(int peer, const float* data, size_t n) = 0;
  virtual Status Receive(int peer, float* data, size_t n) = 0;
  // An error naming `what` unless every process passed the same value (options, scene, resume
  // state: processes that would not train the same model must not start).
  virtual Status CheckSame(const std::string& what, const std::string& value) = 0;
};

// One process: the whole batch is its part.
class LocalViewGroup : public ViewGroup {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  Status SumTree(float*, size_t) override { return Status::Ok(); }
  Status SumDisjoint(double*, size_t) override { return Status::Ok(); }
  Status Max(int*) override { return Status::Ok(); }
  Status Send(int, const float*, size_t) override { return NoPeer(); }
  Status Receive(int, float*, size_t) override { return NoPeer(); }
  Status CheckSame(const std::string&, const std::string&) override { return Status::Ok(); }

 private:
  static Status NoPeer() {
    return Status::Error("one process alone has no other to exchange with");
  }
};

// The positions [*begin, *end) of a batch of `batch` views that process `rank` of `ranks` takes.
inline void BatchPart(int batch, int rank, int ranks, int* begin, int* end) {
  const int part = batch / ranks;
  *begin = rank * part;
  *end = *begin + part;
}

// The number of processes an MPI launcher (mpirun / mpiexec of Open MPI or MPICH, or a PMI-based
// scheduler) started this one among, read from the environment; 0 when none did.
int LaunchedProcesses();

// An error unless `ranks` processes can share batches of `batch` views exactly: a power of two
// that divides the batch.
Status CheckBatchSplit(int batch, int ranks);

// The batch tree over positions [lo, hi): leaf(position, slot) puts one position's value in slot
// `slot`; add(dst, src) adds slot src into slot dst. Slots lo-to-hi depth-first, so at most
// 1 + ceil(log2(hi - lo)) slots are in use (slot `slot` holds the result) and positions are
// visited in order.
template <class Leaf, class Add>
void BatchTreeSum(int lo, int hi, int slot, Leaf&& leaf, Add&& add) {
  if (hi - lo <= 1) {
    leaf(lo, slot);
    return;
  }
  const int mid = lo + (hi - lo) / 2;
  BatchTreeSum(lo, mid, slot, leaf, add);
  BatchTreeSum(mid, hi, slot + 1, leaf, add);
  add(slot, slot + 1);
}

// The slots BatchTreeSum uses for `n` positions.
inline int BatchTreeSlots(int n) {
  int slots = 1;
  while ((1 << (slots - 1)) < n) ++slots;
  return slots;
}

}  // namespace mgsr
