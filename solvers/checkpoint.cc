// Checkpoints of MutualBoostedSolver: a tagged little-endian binary file with everything needed to
// continue a run exactly (models, optimiser states, density statistics, the random generator, the
// view order, the stage, iteration and auto-stop windows). Written atomically.
#include <deque>

#include "mgsr/io/binary_stream.h"
#include "mgsr/io/file_util.h"
#include "solvers/mutual_boosted_solver.h"

namespace mgsr {
namespace {

// Format 2 added the exposure models.
constexpr char kMagic[8] = {'M', 'G', 'S', 'R', 'C', 'K', 'P', '2'};

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

void WriteBlocks(BinaryWriter* w, int max_sh_degree, const std::vector<ParamBlock>& blocks) {
  w->Write<int32_t>(max_sh_degree);
  w->Write<uint32_t>(static_cast<uint32_t>(blocks.size()));
  for (const ParamBlock& b : blocks) {
    w->WriteCString(b.name);
    w->Write<int32_t>(b.width);
    WriteVector(w, *b.data);
  }
}

template <typename Model>
Status ReadModel(BinaryReader* r, Model* m) {
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
    rows = blocks[k].data->size() / width;
  }
  return Status::Ok();
}

void WriteAdam(BinaryWriter* w, const Adam& adam) {
  w->Write<uint32_t>(static_cast<uint32_t>(adam.state().size()));
  for (const auto& [name, s] : adam.state()) {
    w->WriteCString(name);
    w->Write<int32_t>(s.width);
    w->Write<int64_t>(s.step);
    WriteVector(w, s.m);
    WriteVector(w, s.v);
  }
}

Status ReadAdam(BinaryReader* r, Adam* adam) {
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
    adam->state()[name] = std::move(s);
  }
  return Status::Ok();
}

}  // namespace

Status MutualBoostedSolver::SaveCheckpoint(const std::string& path) const {
  BinaryWriter w;
  for (char c : kMagic) w.Write<char>(c);
  w.Write<uint32_t>(static_cast<uint32_t>(train_.size()));
  w.Write<int32_t>(stage_ == Stage::kWarmup ? 0 : 1);
  w.Write<int32_t>(next_iteration_);
  w.Write<uint8_t>(finished_ ? 1 : 0);
  w.Write<int32_t>(sh_degree_);
  const SolveSummary& s = summary_;
  w.Write<int32_t>(s.warmup_iterations_2d);
  w.Write<int32_t>(s.warmup_iterations_3d);
  w.Write<int32_t>(s.mutual_iterations);
  w.Write<uint8_t>(s.auto_stopped_2d);
  w.Write<uint8_t>(s.auto_stopped_3d);
  for (double x : {s.warmup_seconds, s.mutual_seconds, s.final_loss_2d, s.final_loss_3d})
    w.Write<double>(x);
  w.Write<uint64_t>(rng_.state());
  WriteVector(&w, view_stack_);
  WriteVector(&w, std::vector<double>(stop_2d_.window().begin(), stop_2d_.window().end()));
  WriteVector(&w, std::vector<double>(stop_3d_.window().begin(), stop_3d_.window().end()));
  WriteBlocks(&w, gaussians_.max_sh_degree, const_cast<GaussianModel&>(gaussians_).Blocks());
  WriteBlocks(&w, surfels_.max_sh_degree, const_cast<SurfelModel&>(surfels_).Blocks());
  WriteAdam(&w, adam_3d_);
  WriteAdam(&w, adam_2d_);
  for (const DensityStats* st : {&stats_3d_, &stats_2d_}) {
    WriteVector(&w, st->grad_sum);
    WriteVector(&w, st->count);
  }
  w.Write<int32_t>(static_cast<int32_t>(options_.exposure));
  WriteVector(&w, exposure_3d_.SaveState());
  WriteVector(&w, exposure_2d_.SaveState());
  w.Write<double>(s.exposure_fit_seconds);
  return WriteStringToFileAtomic(path, w.data());
}

Status MutualBoostedSolver::LoadCheckpoint(const std::string& path) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  BinaryReader r(path, data);
  char magic[8] = {};
  for (char& c : magic) MGSR_RETURN_IF_ERROR(r.Read(&c));
  if (std::string(magic, 7) != std::string(kMagic, 7))
    return Status::Error(path + ": not an MGSR checkpoint");
  if (magic[7] != kMagic[7]) {
    return Status::Error(path + ": checkpoint format " + std::string(1, magic[7]) +
                         " is from another version of mgsr (this one reads format " +
                         std::string(1, kMagic[7]) + "); start again without --resume");
  }
  uint32_t views = 0;
  MGSR_RETURN_IF_ERROR(r.Read(&views));
  if (views != train_.size()) {
    return Status::Error(path + ": checkpoint was written for " + std::to_string(views) +
                         " training views, this scene has " + std::to_string(train_.size()));
  }
  int32_t stage = 0, next = 0, sh = 0;
  uint8_t finished = 0, a2 = 0, a3 = 0;
  MGSR_RETURN_IF_ERROR(r.Read(&stage));
  MGSR_RETURN_IF_ERROR(r.Read(&next));
  MGSR_RETURN_IF_ERROR(r.Read(&finished));
  MGSR_RETURN_IF_ERROR(r.Read(&sh));
  SolveSummary s;
  MGSR_RETURN_IF_ERROR(r.Read(&s.warmup_iterations_2d));
  MGSR_RETURN_IF_ERROR(r.Read(&s.warmup_iterations_3d));
  MGSR_RETURN_IF_ERROR(r.Read(&s.mutual_iterations));
  MGSR_RETURN_IF_ERROR(r.Read(&a2));
  MGSR_RETURN_IF_ERROR(r.Read(&a3));
  s.auto_stopped_2d = a2 != 0;
  s.auto_stopped_3d = a3 != 0;
  for (double* x : {&s.warmup_seconds, &s.mutual_seconds, &s.final_loss_2d, &s.final_loss_3d}) {
    MGSR_RETURN_IF_ERROR(r.Read(x));
  }
  uint64_t rng_state = 0;
  MGSR_RETURN_IF_ERROR(r.Read(&rng_state));
  std::vector<int> stack;
  std::vector<double> w2, w3;
  MGSR_RETURN_IF_ERROR(ReadVector(&r, &stack));
  MGSR_RETURN_IF_ERROR(ReadVector(&r, &w2));
  MGSR_RETURN_IF_ERROR(ReadVector(&r, &w3));
  GaussianModel g;
  SurfelModel sf;
  MGSR_RETURN_IF_ERROR(ReadModel(&r, &g));
  MGSR_RETURN_IF_ERROR(ReadModel(&r, &sf));
  Adam adam3, adam2;
  MGSR_RETURN_IF_ERROR(ReadAdam(&r, &adam3));
  MGSR_RETURN_IF_ERROR(ReadAdam(&r, &adam2));
  DensityStats st3, st2;
  for (DensityStats* st : {&st3, &st2}) {
    MGSR_RETURN_IF_ERROR(ReadVector(&r, &st->grad_sum));
    MGSR_RETURN_IF_ERROR(ReadVector(&r, &st->count));
  }
  int32_t exposure_mode = 0;
  std::vector<double> e3, e2;
  MGSR_RETURN_IF_ERROR(r.Read(&exposure_mode));
  MGSR_RETURN_IF_ERROR(ReadVector(&r, &e3));
  MGSR_RETURN_IF_ERROR(ReadVector(&r, &e2));
  MGSR_RETURN_IF_ERROR(r.Read(&s.exposure_fit_seconds));
  if (exposure_mode != static_cast<int32_t>(options_.exposure)) {
    return Status::Error(path + ": checkpoint was written with another --exposure mode");
  }
  ExposureModel ex3, ex2;
  const int num_views = static_cast<int>(scene_.views.size());
  if (!ex3.LoadState(e3, num_views, options_.exposure, train_) ||
      !ex2.LoadState(e2, num_views, options_.exposure, train_)) {
    return Status::Error(path + ": corrupt checkpoint (exposure models)");
  }
  if (!r.AtEnd()) return Status::Error(path + ": trailing bytes (corrupt checkpoint)");
  for (int v : stack) {
    if (v < 0 || v >= static_cast<int>(scene_.views.size()))
      return Status::Error(path + ": corrupt checkpoint (view order)");
  }
  // Everything read: commit.
  stage_ = stage == 0 ? Stage::kWarmup : Stage::kMutual;
  next_iteration_ = next;
  finished_ = finished != 0;
  sh_degree_ = sh;
  summary_ = s;
  rng_.set_state(rng_state);
  view_stack_ = std::move(stack);
  stop_2d_.set_window(std::deque<double>(w2.begin(), w2.end()));
  stop_3d_.set_window(std::deque<double>(w3.begin(), w3.end()));
  gaussians_ = std::move(g);
  surfels_ = std::move(sf);
  adam_3d_ = std::move(adam3);
  adam_2d_ = std::move(adam2);
  stats_3d_ = std::move(st3);
  stats_2d_ = std::move(st2);
  exposure_3d_ = std::move(ex3);
  exposure_2d_ = std::move(ex2);
  return Status::Ok();
}

}  // namespace mgsr
