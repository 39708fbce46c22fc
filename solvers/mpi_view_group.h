// The processes of an `mpirun` job as a ViewGroup (solvers/view_group.h), over MPI_COMM_WORLD.
// Built with -DMGSR_WITH_MPI=ON only (the macro MGSR_WITH_MPI is then defined for users of
// mgsr::solvers).
//
// What crosses the wire per step and branch: the parameter gradients and density statistics
// (SumTree: log2(R) exchanges of the whole gradient with one partner each), the batch positions'
// losses, term values and colour-transform gradients (SumDisjoint: a few hundred bytes), and one
// int at each iteration's end (Max). A process that dies ends the job (MPI's default error
// handler; mpirun stops the others), so the last checkpoint, written by process 0 between
// iterations, stays the last good state.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "solvers/view_group.h"

namespace mgsr {

class MpiViewGroup : public ViewGroup {
 public:
  // Whether this process was started by an MPI launcher (LaunchedProcesses() > 0), read from the
  // environment before MPI_Init.
  static bool Launched();
  // Initialises MPI (MPI_Init) and returns the group of MPI_COMM_WORLD; MPI_Finalize runs when
  // it is destroyed. One per process.
  static std::unique_ptr<MpiViewGroup> Init(int* argc, char*** argv);
  ~MpiViewGroup() override;
  MpiViewGroup(const MpiViewGroup&) = delete;
  MpiViewGroup& operator=(const MpiViewGroup&) = delete;

  // Ends every process of the job (MPI_Abort) with `code`: for a process that fails alone while
  // the others may wait for it.
  [[noreturn]] void Abort(int code);

  int rank() const override { return rank_; }
  int size() const override { return size_; }
  Status SumTree(float* data, size_t n) override;
  Status SumDisjoint(double* data, size_t n) override;
  Status Max(int* value) override;
  Status Send(int peer, const float* data, size_t n) override;
  Status Receive(int peer, float* data, size_t n) override;
  Status CheckSame(const std::string& what, const std::string& value) override;

 private:
  MpiViewGroup(int rank, int size) : rank_(rank), size_(size) {}
  int rank_ = 0, size_ = 1;
  std::vector<float> partner_;  // SumTree's receive buffer
};

}  // namespace mgsr
