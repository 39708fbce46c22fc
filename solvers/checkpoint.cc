// Checkpoints of MutualBoostedSolver: a tagged little-endian binary file with everything needed to
// continue a run exactly (models, optimiser states, density statistics, the random generator, the
// view order, the stage, iteration and auto-stop windows). Written atomically.
//
// Format 3: magic, the options it was written under (name = value lines), the scene's fingerprint
// (per view: name and a SHA-256 of its size, camera and split), the state, and a SHA-256 of all of
// it. Loading verifies the checksum first, then refuses other options or another scene naming
// what differs, then checks every value (finite parameters and moments, steps and iterations in
// range) before changing anything.
#include <cmath>
#include <cstdio>
#include <deque>
#include <map>
#include <sstream>

#include "mgsr/core/sha256.h"
#include "mgsr/io/binary_stream.h"
#include "mgsr/io/file_util.h"
#include "solvers/mutual_boosted_solver.h"

namespace mgsr {
namespace {

// Format 2 added the exposure models, 3 the options, the scene fingerprint and the checksum.
constexpr char kMagic[8] = {'M', 'G', 'S', 'R', 'C', 'K', 'P', '3'};
constexpr size_t kChecksumChars = 64;

std::string SettingsText(const SolverOptions& o) {
  std::string text;
  for (const auto& [name, value] : o.Settings()) text += name + " = " + value + "\n";
  return text;
}

// What identifies a view for resuming: its size, camera and split (not the pixels: a re-exported
// photo may differ in its last bit and still be the same view).
std::string ViewFingerprint(const View& v) {
  const Camera& c = v.camera;
  std::string text;
  char number[32];
  auto add = [&](double x) {
    std::snprintf(number, sizeof(number), "%.17g ", x);
    text += number;
  };
  for (double x : {static_cast<double>(c.width), static_cast<double>(c.height), c.fx, c.fy, c.cx,
                   c.cy})
    add(x);
  for (int i = 0; i < 9; ++i) add(c.R(i / 3, i % 3));
  for (int i = 0; i < 3; ++i) add(c.t(i));
  text += v.is_test ? "test" : "train";
  return Sha256Hex(text);
}

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
    if (!AllFinite(*blocks[k].data)) {
      return Status::Error(r->path() + ": checkpoint holds NaN or infinite values in parameter "
                           "block '" + name + "'");
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

}  // namespace

Status MutualBoostedSolver::SaveCheckpoint(const std::string& path) const {
  BinaryWriter w;
  for (char c : kMagic) w.Write<char>(c);
  w.WriteCString(SettingsText(options_));
  w.Write<uint32_t>(static_cast<uint32_t>(scene_.views.size()));
  for (const View& v : scene_.views) {
    w.WriteCString(v.name);
    w.WriteCString(ViewFingerprint(v));
  }
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
  return WriteStringToFileAtomic(path, w.data() + Sha256Hex(w.data()));
}

Status MutualBoostedSolver::LoadCheckpoint(const std::string& path) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  if (data.size() < sizeof(kMagic) || data.compare(0, 7, kMagic, 7) != 0)
    return Status::Error(path + ": not an MGSR checkpoint");
  if (data[7] != kMagic[7]) {
    return Status::Error(path + ": checkpoint format " + std::string(1, data[7]) +
                         " is from another version of mgsr (this one reads format " +
                         std::string(1, kMagic[7]) + "); start again without --resume");
  }
  if (data.size() < sizeof(kMagic) + kChecksumChars ||
      Sha256Hex(data.substr(0, data.size() - kChecksumChars)) !=
          data.substr(data.size() - kChecksumChars)) {
    return Status::Error(path + ": checksum does not match (corrupt or truncated checkpoint)");
  }
  data.resize(data.size() - kChecksumChars);
  BinaryReader r(path, data);
  char magic[8] = {};
  for (char& c : magic) MGSR_RETURN_IF_ERROR(r.Read(&c));

  // The options of the run that wrote it: the first that differs is named.
  std::string settings;
  MGSR_RETURN_IF_ERROR(r.ReadCString(&settings));
  std::map<std::string, std::string> recorded;
  {
    std::istringstream lines(settings);
    std::string line;
    while (std::getline(lines, line)) {
      const size_t eq = line.find(" = ");
      if (eq != std::string::npos) recorded[line.substr(0, eq)] = line.substr(eq + 3);
    }
  }
  for (const auto& [name, value] : options_.Settings()) {
    const auto it = recorded.find(name);
    if (it == recorded.end()) {
      return Status::Error(path + ": the checkpoint does not record option " + name +
                           " (written by another version); start again with --overwrite");
    }
    if (it->second != value) {
      return Status::Error(path + ": the checkpoint was written with " + name + " = " +
                           it->second + ", this run has " + name + " = " + value +
                           "; resume with the options of that run, or start again with --overwrite");
    }
  }
  // The scene: same views in the same order, with the same cameras and split.
  uint32_t all_views = 0;
  MGSR_RETURN_IF_ERROR(r.Read(&all_views));
  if (all_views != scene_.views.size()) {
    return Status::Error(path + ": the checkpoint was written for a scene of " +
                         std::to_string(all_views) + " views, this one has " +
                         std::to_string(scene_.views.size()));
  }
  for (const View& v : scene_.views) {
    std::string name, fingerprint;
    MGSR_RETURN_IF_ERROR(r.ReadCString(&name));
    MGSR_RETURN_IF_ERROR(r.ReadCString(&fingerprint));
    if (name != v.name) {
      return Status::Error(path + ": the checkpoint was written for another scene (view '" +
                           name + "' there, '" + v.name + "' here)");
    }
    if (fingerprint != ViewFingerprint(v)) {
      return Status::Error(path + ": view '" + v.name +
                           "' has another size, camera or split than when the checkpoint was "
                           "written");
    }
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
  const int last = stage == 0 ? options_.warmup_max_iterations : options_.mutual_iterations;
  if (stage < 0 || stage > 1 || next < 1 || next > last + 1 || sh < 0 ||
      sh > options_.sh_degree) {
    return Status::Error(path + ": corrupt checkpoint (stage " + std::to_string(stage) +
                         ", next iteration " + std::to_string(next) + ", SH degree " +
                         std::to_string(sh) + " out of range)");
  }
  if (!AllFinite(w2) || !AllFinite(w3))
    return Status::Error(path + ": corrupt checkpoint (NaN in a loss window)");
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
