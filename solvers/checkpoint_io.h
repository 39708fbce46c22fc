// The pieces of a checkpoint every branch trainer writes the same way: vectors, a model's parameter
// blocks and an Adam state. Readers check what they read (sizes, names, finite values) and report
// the file and the problem; they fill the caller's objects, which the caller commits only once the
// whole file has been read.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "mgsr/io/binary_stream.h"
#include "mgsr/model/param_block.h"
#include "solvers/adam.h"

namespace mgsr {

template <typename Values>
bool AllFinite(const Values& values) {
  for (const auto x : values) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

template <typename T>
void WriteVector(BinaryWriter* w, const std::vector<T>& v) {
  w->Write<uint64_t>(v.size());
  for (const T& x : v) w->Write<T>(x);
}

template <typename T>
Status ReadVector(BinaryReader* r, std::vector<T>* v) {
  uint64_t n = 0;
  MGSR_RETURN_IF_ERROR(r->Read(&n));
  MGSR_RETURN_IF_ERROR(r->CheckRemaining(n, sizeof(T), "values"));
  v->resize(n);
  for (T& x : *v) MGSR_RETURN_IF_ERROR(r->Read(&x));
  return Status::Ok();
}

// A model: its SH degree, then each parameter block by name, width and values.
void WriteModelBlocks(BinaryWriter* w, int max_sh_degree, const std::vector<ParamBlock>& blocks);

// Reads what WriteModelBlocks wrote into `m` (any model with max_sh_degree, Resize and Blocks):
// the blocks must be the model type's, in its order, with rows that agree and finite values.
template <typename Model>
Status ReadModelBlocks(BinaryReader* r, Model* m) {
  int32_t degree = 0;
  uint32_t count = 0;
  MGSR_RETURN_IF_ERROR(r->Read(&degree));
  if (degree < 0 || degree > 3)
    return Status::Error(r->path() + ": corrupt checkpoint (SH degree)");
  m->max_sh_degree = degree;
  m->Resize(0);
  const std::vector<ParamBlock> blocks = m->Blocks();
  MGSR_RETURN_IF_ERROR(r->Read(&count));
  if (count != blocks.size())
    return Status::Error(r->path() + ": checkpoint does not match this model layout");
  size_t rows = 0;
  for (size_t k = 0; k < blocks.size(); ++k) {
    std::string name;
    int32_t width = 0;
    MGSR_RETURN_IF_ERROR(r->ReadCString(&name));
    MGSR_RETURN_IF_ERROR(r->Read(&width));
    if (name != blocks[k].name || width != blocks[k].width) {
      return Status::Error(r->path() + ": checkpoint block '" + name + "' does not match '" +
                           blocks[k].name + "'");
    }
    MGSR_RETURN_IF_ERROR(ReadVector(r, blocks[k].data));
    if (blocks[k].data->size() % width != 0 || (k > 0 && blocks[k].data->size() / width != rows)) {
      return Status::Error(r->path() + ": corrupt checkpoint (block sizes disagree)");
    }
    if (!AllFinite(*blocks[k].data)) {
      return Status::Error(r->path() +
                           ": checkpoint holds NaN or infinite values in parameter "
                           "block '" +
                           name + "'");
    }
    rows = blocks[k].data->size() / width;
  }
  return Status::Ok();
}

// An optimiser: per block its name, width, step count and both moments.
void WriteAdamState(BinaryWriter* w, const Adam& adam);
Status ReadAdamState(BinaryReader* r, Adam* adam);

}  // namespace mgsr
