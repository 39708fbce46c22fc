#include "solvers/checkpoint_io.h"

namespace mgsr {

void WriteModelBlocks(BinaryWriter* w, int max_sh_degree, const std::vector<ParamBlock>& blocks) {
  w->Write<int32_t>(max_sh_degree);
  w->Write<uint32_t>(static_cast<uint32_t>(blocks.size()));
  for (const ParamBlock& b : blocks) {
    w->WriteCString(b.name);
    w->Write<int32_t>(b.width);
    WriteVector(w, *b.data);
  }
}

void WriteAdamState(BinaryWriter* w, const Adam& adam) {
  w->Write<uint32_t>(static_cast<uint32_t>(adam.state().size()));
  for (const auto& [name, s] : adam.state()) {
    w->WriteCString(name);
    w->Write<int32_t>(s.width);
    w->Write<int64_t>(s.step);
    WriteVector(w, s.m);
    WriteVector(w, s.v);
  }
}

Status ReadAdamState(BinaryReader* r, Adam* adam) {
  uint32_t count = 0;
  MGSR_RETURN_IF_ERROR(r->Read(&count));
  if (count > 64) return Status::Error(r->path() + ": corrupt checkpoint (optimiser blocks)");
  adam->state().clear();
  for (uint32_t i = 0; i < count; ++i) {
    std::string name;
    Adam::BlockState s;
    int32_t width = 0;
    MGSR_RETURN_IF_ERROR(r->ReadCString(&name));
    MGSR_RETURN_IF_ERROR(r->Read(&width));
    MGSR_RETURN_IF_ERROR(r->Read(&s.step));
    MGSR_RETURN_IF_ERROR(ReadVector(r, &s.m));
    MGSR_RETURN_IF_ERROR(ReadVector(r, &s.v));
    s.width = width;
    bool v_ok = true;
    for (float x : s.v) v_ok = v_ok && x >= 0;
    if (width <= 0 || s.step < 0 || s.m.size() != s.v.size() || s.m.size() % width != 0 ||
        !AllFinite(s.m) || !AllFinite(s.v) || !v_ok) {
      return Status::Error(r->path() + ": corrupt checkpoint (optimiser state of '" + name +
                           "': negative step, NaN or negative moments, or sizes that disagree)");
    }
    adam->state()[name] = std::move(s);
  }
  return Status::Ok();
}

}  // namespace mgsr
