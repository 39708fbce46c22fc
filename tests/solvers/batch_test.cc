// Batches of views (--batch_views) and processes that share them (ViewGroup): the batch tree's
// order, and a batch split over 2 or 4 processes giving the bits one process gives. The
// processes are simulated by threads sharing memory (ThreadViewGroup below), so the exchange
// logic is tested in every build; the MPI group itself is tested through mgsr_solve under mpirun
// (tests/cli/mpi_test.cc, built with -DMGSR_WITH_MPI=ON).
#include <gtest/gtest.h>
#include <omp.h>

#include <condition_variable>
#include <cstdlib>
#include <deque>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

#include "same_models.h"
#include "short_run.h"
#include "solvers/density_strategy.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/surface_extraction.h"
#include "solvers/view_group.h"
#include "test_util.h"

namespace mgsr {
namespace {

TEST(BatchTreeTest, SumsByRecursiveHalvingAndEveryAlignedPartIsASubtree) {
  // Values whose float sums depend on the order.
  const std::vector<float> x = {1e8f, 1.0f, -1e8f, 3.5f, 0.1f, 7e7f, -7e7f, 0.3f};
  const int n = static_cast<int>(x.size());
  std::vector<float> slots(BatchTreeSlots(n), 0.0f);
  std::vector<int> visited;
  BatchTreeSum(
      0, n, 0,
      [&](int position, int slot) {
        visited.push_back(position);
        slots[slot] = x[position];
      },
      [&](int dst, int src) { slots[dst] += slots[src]; });
  const std::vector<int> in_order = {0, 1, 2, 3, 4, 5, 6, 7};
  EXPECT_EQ(visited, in_order);
  const float expected = ((x[0] + x[1]) + (x[2] + x[3])) + ((x[4] + x[5]) + (x[6] + x[7]));
  EXPECT_EQ(slots[0], expected);
  EXPECT_NE(slots[0], ((((((x[0] + x[1]) + x[2]) + x[3]) + x[4]) + x[5]) + x[6]) + x[7]);
  EXPECT_EQ(BatchTreeSlots(1), 1);
  EXPECT_EQ(BatchTreeSlots(2), 2);
  EXPECT_EQ(BatchTreeSlots(4), 3);
  EXPECT_EQ(BatchTreeSlots(5), 4);
  // A batch of 6 over 2 processes: each part [0, 3), [3, 6) is the tree's subtree.
  int begin = 0, end = 0;
  BatchPart(6, 1, 2, &begin, &end);
  EXPECT_EQ(begin, 3);
  EXPECT_EQ(end, 6);
}

TEST(BatchTreeTest, BatchSplitsAreChecked) {
  EXPECT_TRUE(CheckBatchSplit(4, 2).ok());
  EXPECT_TRUE(CheckBatchSplit(4, 4).ok());
  EXPECT_TRUE(CheckBatchSplit(3, 1).ok());
  const Status odd = CheckBatchSplit(3, 2);
  ASSERT_FALSE(odd.ok());
  EXPECT_NE(odd.message().find("not divisible"), std::string::npos) << odd.message();
  const Status three = CheckBatchSplit(6, 3);
  ASSERT_FALSE(three.ok());
  EXPECT_NE(three.message().find("power of two"), std::string::npos) << three.message();
  EXPECT_FALSE(CheckBatchSplit(0, 1).ok());
}

TEST(BatchTreeTest, TheLaunchersProcessCountIsReadFromTheEnvironment) {
  const char* saved = std::getenv("OMPI_COMM_WORLD_SIZE");
  const std::string keep = saved != nullptr ? saved : "";
  setenv("OMPI_COMM_WORLD_SIZE", "3", 1);
  EXPECT_EQ(LaunchedProcesses(), 3);
  unsetenv("OMPI_COMM_WORLD_SIZE");
  if (std::getenv("PMI_SIZE") == nullptr && std::getenv("MPI_LOCALNRANKS") == nullptr &&
      std::getenv("PMIX_RANK") == nullptr) {
    EXPECT_EQ(LaunchedProcesses(), 0);
  }
  if (saved != nullptr) setenv("OMPI_COMM_WORLD_SIZE", keep.c_str(), 1);
}

// Processes simulated by threads: each "process" runs its own solver in its own thread; the
// group's exchanges meet at a barrier and read each other's buffers.
class SharedBoard {
 public:
  explicit SharedBoard(int size)
      : floats_(size), doubles_(size), ints_(size), texts_(size), size_(size) {}
  int size() const { return size_; }
  void Barrier() {
    std::unique_lock<std::mutex> lock(mutex_);
    const int generation = generation_;
    if (++arrived_ == size_) {
      arrived_ = 0;
      ++generation_;
      cv_.notify_all();
    } else {
      cv_.wait(lock, [&] { return generation != generation_; });
    }
  }
  // Point-to-point messages, per (from, to), in order.
  void Post(int from, int to, std::vector<float> message) {
    std::lock_guard<std::mutex> lock(mutex_);
    mail_[{from, to}].push_back(std::move(message));
    cv_.notify_all();
  }
  std::vector<float> Take(int from, int to) {
    std::unique_lock<std::mutex> lock(mutex_);
    std::deque<std::vector<float>>& box = mail_[{from, to}];
    cv_.wait(lock, [&] { return !box.empty(); });
    std::vector<float> message = std::move(box.front());
    box.pop_front();
    return message;
  }
  std::vector<float*> floats_;
  std::vector<double*> doubles_;
  std::vector<int> ints_;
  std::vector<std::string> texts_;

 private:
  const int size_;
  std::mutex mutex_;
  std::condition_variable cv_;
  int arrived_ = 0, generation_ = 0;
  std::map<std::pair<int, int>, std::deque<std::vector<float>>> mail_;
};

class ThreadViewGroup : public ViewGroup {
 public:
  ThreadViewGroup(SharedBoard* board, int rank) : board_(board), rank_(rank) {}
  int rank() const override { return rank_; }
  int size() const override { return board_->size(); }
  // Recursive doubling, as MpiViewGroup does it.
  Status SumTree(float* data, size_t n) override {
    for (int step = 1; step < size(); step <<= 1) {
      board_->floats_[rank_] = data;
      board_->Barrier();
      const float* other = board_->floats_[rank_ ^ step];
      partner_.assign(other, other + n);
      board_->Barrier();  // both have read before either writes
      for (size_t i = 0; i < n; ++i) data[i] += partner_[i];
    }
    return Status::Ok();
  }
  Status SumDisjoint(double* data, size_t n) override {
    board_->doubles_[rank_] = data;
    board_->Barrier();
    std::vector<double> sum(n, 0.0);
    for (int r = 0; r < size(); ++r)
      for (size_t i = 0; i < n; ++i) sum[i] += board_->doubles_[r][i];
    board_->Barrier();
    std::copy(sum.begin(), sum.end(), data);
    board_->Barrier();
    return Status::Ok();
  }
  Status Max(int* value) override {
    board_->ints_[rank_] = *value;
    board_->Barrier();
    int m = *value;
    for (int v : board_->ints_) m = std::max(m, v);
    board_->Barrier();
    *value = m;
    return Status::Ok();
  }
  Status Send(int peer, const float* data, size_t n) override {
    board_->Post(rank_, peer, std::vector<float>(data, data + n));
    return Status::Ok();
  }
  Status Receive(int peer, float* data, size_t n) override {
    const std::vector<float> message = board_->Take(peer, rank_);
    if (message.size() != n) return Status::Error("message of another size");
    std::copy(message.begin(), message.end(), data);
    return Status::Ok();
  }
  Status CheckSame(const std::string& what, const std::string& value) override {
    board_->texts_[rank_] = value;
    board_->Barrier();
    const bool same = board_->texts_[rank_] == board_->texts_[0];
    board_->Barrier();
    return same ? Status::Ok() : Status::Error(what + " differ");
  }

 private:
  SharedBoard* board_;
  const int rank_;
  std::vector<float> partner_;
};

SolverOptions BatchOptions(int batch) {
  SolverOptions o = testing::ShortFastOptions(40, 12);
  // Densification, opacity resets and SH growth inside the run: the density statistics and the
  // row operations after a summed step are part of what must agree.
  o.schedule_2d = {8, 30, 8, 20, 0.05f};
  o.schedule_3d = {8, 30, 4, 20, 0.005f};
  o.sh_interval = 10;
  o.batch_views = batch;
  return o;
}

using testing::ExpectSameModels;

// One solve per simulated process, each in its own thread; returns them.
std::vector<std::unique_ptr<MutualBoostedSolver>> SolveInThreads(const SolverOptions& o,
                                                                 const Scene& scene, int ranks) {
  SharedBoard board(ranks);
  std::vector<std::unique_ptr<ThreadViewGroup>> groups;
  std::vector<std::unique_ptr<MutualBoostedSolver>> solvers;
  for (int r = 0; r < ranks; ++r) {
    groups.push_back(std::make_unique<ThreadViewGroup>(&board, r));
    solvers.push_back(std::make_unique<MutualBoostedSolver>(o, scene));
    solvers.back()->SetViewGroup(groups.back().get());
  }
  std::vector<Status> status(ranks);
  std::vector<std::thread> threads;
  for (int r = 0; r < ranks; ++r) {
    threads.emplace_back([&, r] {
      omp_set_num_threads(1);  // one core per simulated process
      SolveSummary summary;
      status[r] = solvers[r]->Solve(&summary);
    });
  }
  for (std::thread& t : threads) t.join();
  for (int r = 0; r < ranks; ++r) EXPECT_TRUE(status[r].ok()) << r << ": " << status[r].message();
  return solvers;
}

TEST(BatchTest, ABatchSplitOverProcessesGivesTheModelsOfOneProcess) {
  const Scene scene = testing::TinySolverScene(testing::ScratchDir());
  const SolverOptions o = BatchOptions(4);
  MutualBoostedSolver one(o, scene);
  SolveSummary summary;
  ASSERT_TRUE(one.Solve(&summary).ok());
  EXPECT_EQ(summary.mutual_iterations, 12);
  for (int ranks : {2, 4}) {
    SCOPED_TRACE(std::to_string(ranks) + " processes");
    const auto split = SolveInThreads(o, scene, ranks);
    for (const auto& s : split) ExpectSameModels(one, *s);
  }
  // The batch is real: one view per step trains other models.
  MutualBoostedSolver single(BatchOptions(1), scene);
  ASSERT_TRUE(single.Solve(&summary).ok());
  EXPECT_NE(single.gaussians().means, one.gaussians().means);
}

TEST(BatchTest, TheMeshIsFusedFromFramesTheProcessesRender) {
  // Process 0 fuses every training view in order; process 1 renders every other one for it.
  const Scene scene = testing::TinySolverScene(testing::ScratchDir());
  SolverOptions o = BatchOptions(2);
  o.warmup_max_iterations = 150;  // long enough for an opaque surface
  SurfaceOptions surface;
  std::string note;
  ASSERT_TRUE(ResolveMeshRegion("auto", scene, &surface, &note).ok());
  MutualBoostedSolver one(o, scene);
  SolveSummary summary;
  ASSERT_TRUE(one.Solve(&summary).ok());
  TriangleMesh alone;
  const Status fused = ExtractSurface(&one, o, scene, surface, &alone);
  ASSERT_TRUE(fused.ok()) << fused.message();
  ASSERT_FALSE(alone.empty());
  SharedBoard board(2);
  std::vector<std::unique_ptr<ThreadViewGroup>> groups;
  std::vector<std::unique_ptr<MutualBoostedSolver>> solvers;
  std::vector<TriangleMesh> meshes(2);
  std::vector<Status> status(2);
  for (int r = 0; r < 2; ++r) {
    groups.push_back(std::make_unique<ThreadViewGroup>(&board, r));
    solvers.push_back(std::make_unique<MutualBoostedSolver>(o, scene));
    solvers.back()->SetViewGroup(groups.back().get());
  }
  std::vector<std::thread> threads;
  for (int r = 0; r < 2; ++r) {
    threads.emplace_back([&, r] {
      omp_set_num_threads(1);  // one core per simulated process
      SolveSummary s;
      status[r] = solvers[r]->Solve(&s);
      if (status[r].ok())
        status[r] =
            ExtractSurface(solvers[r].get(), o, scene, surface, &meshes[r], {}, groups[r].get());
    });
  }
  for (std::thread& t : threads) t.join();
  for (int r = 0; r < 2; ++r) ASSERT_TRUE(status[r].ok()) << r << ": " << status[r].message();
  EXPECT_TRUE(meshes[1].empty());
  ASSERT_EQ(meshes[0].vertices.size(), alone.vertices.size());
  ASSERT_EQ(meshes[0].triangles.size(), alone.triangles.size());
  EXPECT_TRUE(meshes[0].vertices == alone.vertices);
  EXPECT_TRUE(meshes[0].triangles == alone.triangles);
  EXPECT_TRUE(meshes[0].vertex_colors == alone.vertex_colors);
}

// Asks `solver` to stop at the end of iteration `iteration` of `stage`.
struct StopAfter : IterationCallback {
  StopAfter(MutualBoostedSolver* s, Stage st, int it) : solver(s), stage(st), iteration(it) {}
  CallbackReturnType operator()(const IterationInfo&) override {
    return CallbackReturnType::kContinue;
  }
  CallbackReturnType OnIterationEnd(const MutualBoostedSolver&, Stage s, int it) override {
    if (s == stage && it == iteration) solver->RequestStop();
    return CallbackReturnType::kContinue;
  }
  MutualBoostedSolver* solver;
  Stage stage;
  int iteration;
};

// Solves s0 here and s1 in a second thread (one core each); both must end without error.
void SolveTwo(MutualBoostedSolver* s0, MutualBoostedSolver* s1, SolveSummary* r0,
              SolveSummary* r1) {
  std::thread t([&] {
    omp_set_num_threads(1);
    ASSERT_TRUE(s1->Solve(r1).ok());
  });
  ASSERT_TRUE(s0->Solve(r0).ok());
  t.join();
}

// A job of two simulated processes in which process `stopper` asks to stop after iteration
// `iteration` of `stage`: solved on construction.
struct StoppedPair {
  StoppedPair(const SolverOptions& o, const Scene& scene, int stopper, Stage stage, int iteration)
      : g0(&board, 0),
        g1(&board, 1),
        s0(o, scene),
        s1(o, scene),
        stop(stopper == 0 ? &s0 : &s1, stage, iteration) {
    s0.SetViewGroup(&g0);
    s1.SetViewGroup(&g1);
    (stopper == 0 ? s0 : s1).AddCallback(&stop);
    SolveTwo(&s0, &s1, &r0, &r1);
  }
  SharedBoard board{2};
  ThreadViewGroup g0, g1;
  MutualBoostedSolver s0, s1;
  StopAfter stop;
  SolveSummary r0, r1;
};

TEST(BatchTest, AProcessThatStopsStopsTheGroup) {
  // Process 1 alone asks to stop after its third iteration; both end there, at the same state.
  const Scene scene = testing::TinySolverScene(testing::ScratchDir());
  const StoppedPair p(BatchOptions(2), scene, 1, Stage::kWarmup, 3);
  EXPECT_EQ(p.r0.termination_type, TerminationType::kInterrupted);
  EXPECT_EQ(p.r1.termination_type, TerminationType::kInterrupted);
  EXPECT_EQ(p.r0.branch(Branch::kGaussians3D).warmup_iterations, 3);
  EXPECT_EQ(p.r1.branch(Branch::kGaussians3D).warmup_iterations, 3);
  ExpectSameModels(p.s0, p.s1);
}

// Stopped over two processes between the two steps of a mutual round (after the 2DGS step of
// iteration 3), process 0's checkpoint resumes in one process to the models of an uninterrupted
// run: it holds the depth each process's 2DGS step kept for the 3DGS step, also of the views the
// other process rendered (ShareStepBuffers).
TEST(BatchTest, ACheckpointBetweenTheStepsOfARoundResumesInAnyProcessCount) {
  const std::string dir = testing::ScratchDir();
  const Scene scene = testing::TinySolverScene(dir);
  const SolverOptions o = BatchOptions(4);
  MutualBoostedSolver whole(o, scene);
  SolveSummary summary;
  ASSERT_TRUE(whole.Solve(&summary).ok());
  const StoppedPair p(o, scene, 0, Stage::kMutual, 3);
  ASSERT_EQ(p.r0.termination_type, TerminationType::kInterrupted);
  ASSERT_EQ(p.r0.mutual_iterations, 3);
  const std::string checkpoint = dir + "/round.ckpt";
  ASSERT_TRUE(p.s0.SaveCheckpoint(checkpoint).ok());
  MutualBoostedSolver resumed(o, scene);
  ASSERT_TRUE(resumed.LoadCheckpoint(checkpoint).ok());
  ASSERT_TRUE(resumed.Solve(&summary).ok());
  EXPECT_EQ(summary.mutual_iterations, 12);
  ExpectSameModels(whole, resumed);
}

// A density strategy that counts, per primitive, the views of a step that drew it.
struct DrawnCount : DensityStrategy {
  static int most;
  int ViewStatisticsWidth(int) const override { return 1; }
  void ViewStatistics(const DensityView& view, float* out) override {
    for (size_t i = 0; i < view.radii->size(); ++i) out[i] = (*view.radii)[i] > 0 ? 1.0f : 0.0f;
  }
  double BeforeStep(const DensityStep& step, const PrimitiveRows&,
                    const std::vector<ParamBlock>&) override {
    EXPECT_EQ(step.views, 3);
    for (float drawn : *step.statistics) most = std::max(most, static_cast<int>(drawn));
    return 0;
  }
  DensifyResult AfterStep(const DensityStep&, PrimitiveRows*, Rng*) override { return {}; }
  void Save(BinaryWriter*) const override {}
  Status Read(BinaryReader*) override { return Status::Ok(); }
  void CommitRead() override {}
};
int DrawnCount::most = 0;

TEST(BatchTest, DensityStatisticsAreSummedOverTheBatch) {
  DensityStrategyRegistry::Get().Register(
      "drawn_count", [](const DensityContext&, const nlohmann::json&, Status*) {
        return std::unique_ptr<DensityStrategy>(new DrawnCount);
      });
  const Scene scene = testing::TinySolverScene(testing::ScratchDir());
  SolverOptions o = BatchOptions(3);
  o.density = "drawn_count";
  o.warmup_max_iterations = 4;
  o.mutual_iterations = 0;
  MutualBoostedSolver solver(o, scene);
  SolveSummary summary;
  ASSERT_TRUE(solver.Solve(&summary).ok());
  EXPECT_EQ(DrawnCount::most, 3);  // a primitive every view of a batch draws
}

TEST(BatchTest, IterationCountsScaleWithTheBatch) {
  SolverOptions o;
  SolverOptions::FromPreset("fast", &o);
  o.losses = o.LossTable();
  const SolverOptions before = o;
  o.ScaleIterationsForBatch(4);
  EXPECT_EQ(o.warmup_max_iterations, before.warmup_max_iterations / 4);
  EXPECT_EQ(o.mutual_iterations, before.mutual_iterations / 4);
  EXPECT_EQ(o.schedule_3d.densify_interval, before.schedule_3d.densify_interval / 4);
  EXPECT_EQ(o.schedule_2d.densify_until, before.schedule_2d.densify_until / 4);
  EXPECT_EQ(o.normal_from_iteration, (before.normal_from_iteration + 2) / 4);
  bool scaled_row = false;
  for (size_t i = 0; i < o.losses.size(); ++i) {
    if (before.losses[i].first_iteration > 1) {
      EXPECT_LT(o.losses[i].first_iteration, before.losses[i].first_iteration);
      scaled_row = true;
    }
  }
  EXPECT_TRUE(scaled_row);
  SolverOptions same = before;
  same.ScaleIterationsForBatch(1);
  EXPECT_EQ(same.Settings(), before.Settings());
  // Bidirectional supervision steps one view at a time.
  o.bidirectional = true;
  o.batch_views = 2;
  EXPECT_FALSE(o.Validate().ok());
}

}  // namespace
}  // namespace mgsr
