// Trains a small synthetic scene with the paper's loss table plus the rows of a JSON file, one of
// which uses the term defined in alpha_binary_loss.h. Prints each step's value of the new row and
// the solver's report; exits non-zero if the row never trained or the solve failed.
//   custom_loss LOSSES.json WORK_DIR
#include <cstdio>
#include <memory>
#include <string>

#include "alpha_binary_loss.h"
#include "mgsr/io/scene.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/synth/synthetic_scene.h"
#include "mgsr/version.h"
#include "solvers/loss_table.h"
#include "solvers/mutual_boosted_solver.h"

namespace {

// Counts the steps where the row `name` was active and prints its weighted value now and then.
class RowWatcher : public mgsr::IterationCallback {
 public:
  explicit RowWatcher(std::string name) : name_(std::move(name)) {}
  mgsr::CallbackReturnType operator()(const mgsr::IterationInfo& info) override {
    for (const mgsr::Problem::TermValue& t : info.terms) {
      if (t.name != name_) continue;
      if (++steps_ % 20 == 1) {
        std::printf("%s %s iteration %d: %s = %.5f (of loss %.5f)\n", mgsr::StageName(info.stage),
                    info.branch == mgsr::Branch::kSurfels2D ? "2DGS" : "3DGS", info.iteration,
                    name_.c_str(), t.weight * t.value, info.loss);
      }
    }
    return mgsr::CallbackReturnType::kContinue;
  }
  int steps() const { return steps_; }

 private:
  std::string name_;
  int steps_ = 0;
};

int Fail(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) return Fail("usage: custom_loss LOSSES.json WORK_DIR");
  std::printf("mgsr %s\n", MGSR_VERSION_STRING);
  // The one registration line.
  mgsr::LossRegistry::Get().Register("alpha_binary", [](const nlohmann::json&, mgsr::Status*) {
    return std::make_unique<AlphaBinaryLoss>();
  });

  mgsr::SynthOptions synth;
  synth.width = synth.height = 48;
  synth.num_views = 16;
  synth.num_points = 300;
  const std::string scene_dir = std::string(argv[2]) + "/scene";
  mgsr::Status s = mgsr::WriteSyntheticScene(synth, scene_dir);
  mgsr::Scene scene;
  if (s.ok()) s = mgsr::LoadScene(scene_dir, mgsr::SceneOptions(), &scene);
  if (!s.ok()) return Fail(s.message());

  mgsr::SolverOptions options;
  mgsr::SolverOptions::FromPreset("fast", &options);
  options.warmup_min_iterations = 0;
  options.warmup_max_iterations = 100;
  options.mutual_iterations = 20;
  options.auto_stop = false;
  options.losses = options.LossTable();  // the paper's rows, then the file's
  s = mgsr::ApplyLossConfigFile(argv[1], &options.losses);
  if (!s.ok()) return Fail(s.message());

  mgsr::MutualBoostedSolver solver(options, scene);
  RowWatcher watcher("crisp_alpha");
  solver.AddCallback(&watcher);
  mgsr::SolveSummary summary;
  s = solver.Solve(&summary);
  std::printf("%s", summary.FullReport().c_str());
  if (!s.ok()) return Fail(s.message());
  if (watcher.steps() == 0) return Fail("the row crisp_alpha never trained");
  std::printf("crisp_alpha trained in %d steps\n", watcher.steps());
  return 0;
}
