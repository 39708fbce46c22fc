#include "solvers/view_group.h"

#include <algorithm>
#include <cstdlib>

namespace mgsr {

int LaunchedProcesses() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "MPI_LOCALNRANKS"}) {
    if (const char* value = std::getenv(name)) return std::max(1, std::atoi(value));
  }
  return std::getenv("PMIX_RANK") != nullptr ? 1 : 0;
}

Status CheckBatchSplit(int batch, int ranks) {
  if (batch < 1)
    return Status::Error("--batch_views must be at least 1 (got " + std::to_string(batch) + ")");
  if (ranks < 1 || (ranks & (ranks - 1)) != 0) {
    return Status::Error(std::to_string(ranks) +
                         " processes: the number of MPI ranks must be a power of two (1, 2, 4, "
                         "...), so that every rank's part of a batch is a subtree of its sum");
  }
  if (batch % ranks != 0) {
    return Status::Error("--batch_views " + std::to_string(batch) + " is not divisible by the " +
                         std::to_string(ranks) + " MPI ranks: every rank takes the same number " +
                         "of views of each batch");
  }
  return Status::Ok();
}

}  // namespace mgsr
