// Checkpoints of MutualBoostedSolver: a tagged little-endian binary file with everything needed to
// continue a run exactly (models, optimiser states, density statistics, the random generator, the
// view order, the stage, iteration and auto-stop windows). Written atomically.
//
// Format 4: magic, the options it was written under (name = value lines), the scene's fingerprint
// (per view: name and a SHA-256 of its size, camera and split), the solver's state, each branch
// trainer's state (BranchTrainer::Save, 2DGS then 3DGS), and a SHA-256 of all of it. Loading
// verifies the checksum first, then refuses other options or another scene naming what differs,
// then checks every value (finite parameters and moments, steps and iterations in range) before
// changing anything.
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "mgsr/core/sha256.h"
#include "mgsr/io/binary_stream.h"
#include "mgsr/io/file_util.h"
#include "solvers/checkpoint_io.h"
#include "solvers/mutual_boosted_solver.h"

namespace mgsr {
namespace {

// Format 2 added the exposure models, 3 the options, the scene fingerprint and the checksum, 4
// wrote each branch through its trainer, 5 added each trainer's kept step buffers.
constexpr char kMagic[8] = {'M', 'G', 'S', 'R', 'C', 'K', 'P', '5'};
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
  for (double x :
       {static_cast<double>(c.width), static_cast<double>(c.height), c.fx, c.fy, c.cx, c.cy})
    add(x);
  for (int i = 0; i < 9; ++i) add(c.R(i / 3, i % 3));
  for (int i = 0; i < 3; ++i) add(c.t(i));
  text += v.is_test ? "test" : "train";
  return Sha256Hex(text);
}

}  // namespace

std::string MutualBoostedSolver::SettingsFingerprint() const { return SettingsText(options_); }

std::string MutualBoostedSolver::SceneFingerprint() const {
  std::string text;
  for (const View& v : scene_.views) text += v.name + " " + ViewFingerprint(v) + "\n";
  return text;
}

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
  w.Write<int32_t>(s.mutual_iterations);
  for (double x : {s.warmup_seconds, s.mutual_seconds, s.exposure_fit_seconds}) w.Write<double>(x);
  w.Write<uint64_t>(rng_.state());
  WriteVector(&w, view_stack_);
  w.Write<int32_t>(static_cast<int32_t>(options_.exposure));
  for (const ExposureModel& e : exposures_) WriteVector(&w, e.SaveState());
  for (const BranchTrainer* t : trainers_) t->Save(&w);
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
    // Options added after a checkpoint was written, with the value runs had before them.
    // (A run from before lambda_normal_tv whose normal TV was 2.0 is still refused: the loss
    // table it recorded, option "losses", differs.)
    static const std::map<std::string, std::string> kBefore = {{"coarse", "none"},
                                                               {"lambda_mask_warmup", "-1"},
                                                               {"lambda_normal_tv", "0.05"},
                                                               {"lambda_surfel_layer", "0"},
                                                               {"mutual_iterations_2d", "-1"},
                                                               {"normal_agreement_floor", "1"},
                                                               {"position_lr_max_steps_2d", "-1"},
                                                               {"spread_initial_surfels", "0"},
                                                               {"surfel_shape_decay", "0"}};
    const auto before = kBefore.find(name);
    if (it == recorded.end() && before != kBefore.end() && before->second == value) continue;
    if (it == recorded.end()) {
      return Status::Error(path + ": the checkpoint does not record option " + name +
                           " (written by another version); start again with --overwrite");
    }
    if (it->second != value) {
      // Options the pipeline derives from the scene rather than from a flag of their own: say
      // which flags move them, since the user changed one of those.
      std::string hint;
      if (name == "max_gaussians" || name == "max_surfels")
        hint =
            " (derived from the scene's size in pixels and --budget: did --downscale, "
            "--max_size, --max_width, --budget or the photos change?)";
      else if (name == "lambda_normal" || name == "lambda_mask")
        hint = " (derived from whether the views have masks, unless --" + name + " is given)";
      else if (name == "mutual_iterations_2d" || name == "schedule_2d")
        hint =
            " (derived from whether the views have masks and the mutual stage's length, unless "
            "--mutual_iterations_2d is given)";
      else if (name == "coarse")
        hint = " (derived from --coarse_max_size and the photos' size, with --coarse_fraction)";
      else if (name == "background_2d" || name == "background_3d" || name == "environment")
        hint = " (derived from --background and the photos' borders)";
      return Status::Error(
          path + ": the checkpoint was written with " + name + " = " + it->second +
          ", this run has " + name + " = " + value + hint +
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
      return Status::Error(path + ": the checkpoint was written for another scene (view '" + name +
                           "' there, '" + v.name + "' here)");
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
  uint8_t finished = 0;
  MGSR_RETURN_IF_ERROR(r.Read(&stage));
  MGSR_RETURN_IF_ERROR(r.Read(&next));
  MGSR_RETURN_IF_ERROR(r.Read(&finished));
  MGSR_RETURN_IF_ERROR(r.Read(&sh));
  SolveSummary s;
  MGSR_RETURN_IF_ERROR(r.Read(&s.mutual_iterations));
  for (double* x : {&s.warmup_seconds, &s.mutual_seconds, &s.exposure_fit_seconds}) {
    MGSR_RETURN_IF_ERROR(r.Read(x));
  }
  uint64_t rng_state = 0;
  std::vector<int> stack;
  MGSR_RETURN_IF_ERROR(r.Read(&rng_state));
  MGSR_RETURN_IF_ERROR(ReadVector(&r, &stack));
  int32_t exposure_mode = 0;
  MGSR_RETURN_IF_ERROR(r.Read(&exposure_mode));
  if (exposure_mode != static_cast<int32_t>(options_.exposure)) {
    return Status::Error(path + ": checkpoint was written with another --exposure mode");
  }
  ExposureModel exposures[2];
  const int num_views = static_cast<int>(scene_.views.size());
  for (ExposureModel& e : exposures) {
    std::vector<double> state;
    MGSR_RETURN_IF_ERROR(ReadVector(&r, &state));
    if (!e.LoadState(state, num_views, options_.exposure, train_))
      return Status::Error(path + ": corrupt checkpoint (exposure models)");
  }
  // Each trainer keeps what it read aside until the commit below.
  for (BranchTrainer* t : trainers_) MGSR_RETURN_IF_ERROR(t->Read(&r));
  if (!r.AtEnd()) return Status::Error(path + ": trailing bytes (corrupt checkpoint)");
  for (int v : stack) {
    if (v < 0 || v >= static_cast<int>(scene_.views.size()))
      return Status::Error(path + ": corrupt checkpoint (view order)");
  }
  const int last = stage == 0 ? options_.warmup_max_iterations : options_.mutual_iterations;
  if (stage < 0 || stage > 1 || next < 1 || next > last + 1 || sh < 0 || sh > options_.sh_degree) {
    return Status::Error(path + ": corrupt checkpoint (stage " + std::to_string(stage) +
                         ", next iteration " + std::to_string(next) + ", SH degree " +
                         std::to_string(sh) + " out of range)");
  }
  // Values no run writes (a hand edit whose checksum was recomputed): a finished flag other than
  // 0/1 or set before the mutual stage's end, and the generator's state 0 (splitmix64 from any
  // seed meets it with probability 2^-64 per draw).
  if (finished > 1 || (finished == 1 && !(stage == 1 && next == options_.mutual_iterations + 1))) {
    return Status::Error(path + ": corrupt checkpoint (marked finished at stage " +
                         std::to_string(stage) + ", next iteration " + std::to_string(next) + ")");
  }
  if (rng_state == 0)
    return Status::Error(path + ": corrupt checkpoint (random generator state 0)");
  // Everything read: commit.
  stage_ = stage == 0 ? Stage::kWarmup : Stage::kMutual;
  next_iteration_ = next;
  finished_ = finished != 0;
  SetShDegree(sh);
  summary_ = s;
  rng_.set_state(rng_state);
  view_stack_ = std::move(stack);
  for (int k = 0; k < 2; ++k) exposures_[k] = std::move(exposures[k]);
  for (BranchTrainer* t : trainers_) t->CommitRead();
  return Status::Ok();
}

}  // namespace mgsr
