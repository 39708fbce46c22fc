#include "solvers/mpi_view_group.h"

#include <mpi.h>

#include <algorithm>
#include <climits>
#include <cstdlib>
#include <vector>

#include "mgsr/core/sha256.h"

namespace mgsr {
namespace {

// MPI counts are ints: long arrays go in pieces of at most this many elements.
constexpr size_t kMaxCount = size_t{1} << 28;

Status MpiError(const char* call, int code) {
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  MPI_Error_string(code, text, &length);
  return Status::Error(std::string("MPI: ") + call + " failed: " + std::string(text, length));
}

}  // namespace

bool MpiViewGroup::Launched() { return LaunchedProcesses() > 0; }

std::unique_ptr<MpiViewGroup> MpiViewGroup::Init(int* argc, char*** argv) {
  MPI_Init(argc, argv);
  // Errors come back as codes, so that a failed call ends this process with a message naming
  // it (mpirun then stops the others) instead of an abort without one.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  return std::unique_ptr<MpiViewGroup>(new MpiViewGroup(rank, size));
}

MpiViewGroup::~MpiViewGroup() { MPI_Finalize(); }

void MpiViewGroup::Abort(int code) {
  MPI_Abort(MPI_COMM_WORLD, code);
  std::exit(code);  // not reached: MPI_Abort ends the process
}

Status MpiViewGroup::SumTree(float* data, size_t n) {
  // Recursive doubling: at level l the processes of each aligned block of 2^(l+1) add the sums of
  // its two halves (exchanged with the partner rank ^ 2^l). Both partners add the same two
  // floats, so they hold the same bits, and the levels are those of the batch tree.
  if (size_ == 1 || n == 0) return Status::Ok();
  partner_.resize(std::min(n, kMaxCount));
  for (int step = 1; step < size_; step <<= 1) {
    const int partner = rank_ ^ step;
    for (size_t begin = 0; begin < n; begin += kMaxCount) {
      const int count = static_cast<int>(std::min(kMaxCount, n - begin));
      const int code =
          MPI_Sendrecv(data + begin, count, MPI_FLOAT, partner, step, partner_.data(), count,
                       MPI_FLOAT, partner, step, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      if (code != MPI_SUCCESS) return MpiError("MPI_Sendrecv", code);
      float* d = data + begin;
      const float* p = partner_.data();
      for (int i = 0; i < count; ++i) d[i] += p[i];
    }
  }
  return Status::Ok();
}

Status MpiViewGroup::SumDisjoint(double* data, size_t n) {
  for (size_t begin = 0; begin < n; begin += kMaxCount) {
    const int count = static_cast<int>(std::min(kMaxCount, n - begin));
    const int code =
        MPI_Allreduce(MPI_IN_PLACE, data + begin, count, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
    if (code != MPI_SUCCESS) return MpiError("MPI_Allreduce", code);
  }
  return Status::Ok();
}

Status MpiViewGroup::Max(int* value) {
  const int code = MPI_Allreduce(MPI_IN_PLACE, value, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  return code == MPI_SUCCESS ? Status::Ok() : MpiError("MPI_Allreduce", code);
}

Status MpiViewGroup::Send(int peer, const float* data, size_t n) {
  for (size_t begin = 0; begin < n; begin += kMaxCount) {
    const int count = static_cast<int>(std::min(kMaxCount, n - begin));
    const int code = MPI_Send(data + begin, count, MPI_FLOAT, peer, 0, MPI_COMM_WORLD);
    if (code != MPI_SUCCESS) return MpiError("MPI_Send", code);
  }
  return Status::Ok();
}

Status MpiViewGroup::Receive(int peer, float* data, size_t n) {
  for (size_t begin = 0; begin < n; begin += kMaxCount) {
    const int count = static_cast<int>(std::min(kMaxCount, n - begin));
    const int code =
        MPI_Recv(data + begin, count, MPI_FLOAT, peer, 0, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    if (code != MPI_SUCCESS) return MpiError("MPI_Recv", code);
  }
  return Status::Ok();
}

Status MpiViewGroup::CheckSame(const std::string& what, const std::string& value) {
  // Every process compares the digests of all (64 hex characters each).
  const std::string mine = Sha256Hex(value);
  std::vector<char> all(mine.size() * size_);
  const int code = MPI_Allgather(mine.data(), static_cast<int>(mine.size()), MPI_CHAR, all.data(),
                                 static_cast<int>(mine.size()), MPI_CHAR, MPI_COMM_WORLD);
  if (code != MPI_SUCCESS) return MpiError("MPI_Allgather", code);
  for (int r = 1; r < size_; ++r) {
    if (std::string(all.data() + r * mine.size(), mine.size()) !=
        std::string(all.data(), mine.size())) {
      return Status::Error("MPI process " + std::to_string(r) + " has other " + what +
                           " than process 0: every process must run the same command on the "
                           "same files");
    }
  }
  return Status::Ok();
}

}  // namespace mgsr
