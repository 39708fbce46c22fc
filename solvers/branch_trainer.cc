#include "solvers/branch_trainer.h"

#include <glog/logging.h>

#include <algorithm>
#include <limits>

#include "mgsr/core/profiler.h"

namespace mgsr {
namespace {
// More batch positions than any batch has: a larger count in a checkpoint is damage.
constexpr uint32_t kMaxKeptBuffers = 1u << 16;
}  // namespace

const char* BranchLabel(Branch branch) { return branch == Branch::kSurfels2D ? "2DGS" : "3DGS"; }

BranchTrainer::BranchTrainer(Branch branch, const BranchTrainerOptions& options,
                             ExposureModel* exposure, Rng* rng)
    : branch_(branch),
      options_(options),
      exposure_(exposure),
      rng_(rng),
      auto_stop_(options.auto_stop_min_iteration, options.auto_stop_window,
                 options.auto_stop_range) {
  DensityContext context;
  context.schedule = options.schedule;
  context.density = options.density;
  context.extent = options.extent;
  Status status;
  density_ = DensityStrategyRegistry::Get().Create(options.density_strategy, context,
                                                   options.density_config, &status);
  CHECK(density_ != nullptr) << BranchLabel(branch) << ": " << status.message();
  if (options.environment)
    environment_ = std::make_unique<EnvironmentBackground>(options.environment_options);
}

void BranchTrainer::BindRows(std::vector<ParamBlock> params) {
  rows_ = std::make_unique<PrimitiveRows>(std::move(params), &adam_, &Layout());
}

void BranchTrainer::BeginDensity(std::vector<ParamBlock> params) {
  BindRows(std::move(params));
  density_->Begin(rows_.get(), rng_);
}

void BranchTrainer::AddLossRow(const LossSpec& row, std::unique_ptr<LossTerm> term,
                               bool behind_exposure) {
  StageProblem& sp = ProblemFor(row.stage);
  if (behind_exposure) {
    auto wrapped = std::make_unique<ExposureCompensatedLoss>(std::move(term));
    sp.exposure_terms.push_back(wrapped.get());
    term = std::move(wrapped);
  }
  BufferSet reads = 0;  // differentiated or read as constants
  for (const std::vector<Buffer>& list : {term->Inputs(), term->ConstantInputs()})
    for (Buffer b : list) reads |= BufferBit(b);
  sp.problem.AddTerm(std::move(term), row.weight, branch_, row.name);
  sp.rows.push_back(row);
  sp.reads.push_back(reads);
}

Status BranchTrainer::AddPriorRow(const LossSpec& row, std::unique_ptr<PrimitivePrior> prior) {
  const Status s = prior->Check(rows_->blocks());
  if (!s.ok())
    return s.WithContext("loss row " + LossSpecId(row) + " (" + row.term + ") on the " + name() +
                         " model: ");
  StageProblem& sp = ProblemFor(row.stage);
  sp.prior_rows.push_back(row);
  sp.priors.push_back(std::move(prior));
  return Status::Ok();
}

double BranchTrainer::EvaluatePriors(Stage stage, int iteration, int count,
                                     const std::vector<ParamBlock>& gradients) {
  StageProblem& sp = ProblemFor(stage);
  active_priors_ = 0;
  double total = 0;
  for (size_t i = 0; i < sp.priors.size(); ++i) {
    const LossSpec& row = sp.prior_rows[i];
    const double weight = RowWeightAt(row, iteration);
    if (weight == 0) continue;
    const double value = sp.priors[i]->Evaluate(rows_->blocks(), weight * count, &gradients);
    Problem::SetTermValue(&prior_terms_, active_priors_++, row.name, weight, value);
    total += weight * value;
  }
  return total;
}

double BranchTrainer::RowWeightAt(const LossSpec& row, int iteration) {
  return iteration >= row.first_iteration ? row.weight : 0.0;
}

BufferSet BranchTrainer::StageReads(Stage stage, int iteration) const {
  const StageProblem& sp = ProblemFor(stage);
  BufferSet reads = 0;
  for (size_t i = 0; i < sp.rows.size(); ++i)
    if (RowWeightAt(sp.rows[i], iteration) != 0) reads |= sp.reads[i];
  return reads;
}

bool BranchTrainer::StageReadsNeighbourDepth(Stage stage, int iteration) const {
  const StageProblem& sp = ProblemFor(stage);
  const auto& entries = sp.problem.entries();
  for (size_t i = 0; i < sp.rows.size() && i < entries.size(); ++i)
    if (RowWeightAt(sp.rows[i], iteration) != 0 && entries[i].term->ReadsNeighbourDepth())
      return true;
  return false;
}

double BranchTrainer::EvaluateLoss(Stage stage, int view, int iteration, const RenderBuffers& in,
                                   const Targets& targets, RenderGradients* gradient) {
  ProfileScope scope("losses");
  StageProblem& sp = ProblemFor(stage);
  size_t active = 0;
  for (size_t i = 0; i < sp.rows.size(); ++i) {
    const double weight = RowWeightAt(sp.rows[i], iteration);
    sp.problem.SetWeight(i, weight);
    active += weight != 0;
  }
  for (ExposureCompensatedLoss* e : sp.exposure_terms) e->set_transform(exposure_->transform(view));
  if (active != sp.checked_active) {
    // When the set of active rows changes (rows start at their first iteration): every active
    // row's inputs and targets exist (a custom row may ask for a buffer this branch does not
    // render, or a target this stage does not have).
    const Status s = sp.problem.Check(branch_, in, targets);
    if (!s.ok()) {
      step_error_ = s.WithContext(std::string(name()) + " " + StageName(stage) + " loss row ");
      return std::numeric_limits<double>::quiet_NaN();
    }
    sp.checked_active = active;
  }
  // LastTerms() is set once the density strategy's regulariser is known (OptimizeAndControlDensity,
  // or Step when the step ends at the loss), so its size stays the same from step to step.
  const double loss = sp.problem.Evaluate(branch_, in, targets, gradient, &loss_terms_);
  exposure_gradient_.fill(0.0);
  for (const ExposureCompensatedLoss* e : sp.exposure_terms) {
    for (int k = 0; k < kColorTransformSize; ++k)
      exposure_gradient_[k] += e->parameter_gradient()[k];
  }
  return loss;
}

double BranchTrainer::Step(Stage stage, int view, const Camera& camera, int iteration,
                           const Targets& targets) {
  struct Fixed : BatchTargets {
    explicit Fixed(const Targets& t) : targets(t) {}
    Targets For(int) override { return targets; }
    Targets targets;
  } fixed(targets);
  const BatchView one{view, &camera};
  LocalViewGroup local;
  return StepBatch(stage, &one, 1, &fixed, iteration, &local);
}

void BranchTrainer::BeginBatch(Stage stage, int count) {
  position_stride_ = 1 + kColorTransformSize + ProblemFor(stage).rows.size();
  position_values_.assign(position_stride_ * count, 0.0);
  if (keep_step_buffer_) {
    // Grows only (the images keep their storage between steps).
    if (kept_.size() < static_cast<size_t>(count)) kept_.resize(count);
    for (KeptBuffer& k : kept_) k.view = -1;
  }
}

void BranchTrainer::KeepFromStep(int position, int view, const RenderBuffers& buffers) {
  if (!keep_step_buffer_) return;
  const Image* image = buffers.Get(kept_buffer_);
  if (image == nullptr || image->empty()) return;
  KeptBuffer& k = kept_[position];
  k.image = *image;
  k.view = view;
}

void BranchTrainer::ShareStepBuffers(const BatchView* views, int count, ViewGroup* group) {
  if (!keep_step_buffer_) return;
  ProfileScope scope("batch sum");
  int begin = 0, end = count;
  BatchPart(count, group->rank(), group->size(), &begin, &end);
  // Each position belongs to one process: its shape, then its values, summed over the
  // processes where every other process holds zeros (exact in any order).
  shared_shapes_.assign(3 * static_cast<size_t>(count), 0.0);
  for (int p = begin; p < end; ++p) {
    const Image& image = kept_[p].image;
    if (kept_[p].view < 0) continue;
    shared_shapes_[3 * p] = image.width();
    shared_shapes_[3 * p + 1] = image.height();
    shared_shapes_[3 * p + 2] = image.channels();
  }
  Status s = group->SumDisjoint(shared_shapes_.data(), shared_shapes_.size());
  if (!s.ok()) {
    step_error_ = s;
    return;
  }
  const auto size_of = [&](int p) {
    return static_cast<size_t>(shared_shapes_[3 * p]) *
           static_cast<size_t>(shared_shapes_[3 * p + 1]) *
           static_cast<size_t>(shared_shapes_[3 * p + 2]);
  };
  size_t total = 0;
  for (int p = 0; p < count; ++p) total += size_of(p);
  shared_data_.assign(total, 0.0f);
  size_t offset = 0;
  for (int p = 0; p < count; ++p) {
    if (p >= begin && p < end && kept_[p].view >= 0)
      std::copy(kept_[p].image.data(), kept_[p].image.data() + size_of(p),
                shared_data_.data() + offset);
    offset += size_of(p);
  }
  s = group->SumTree(shared_data_.data(), shared_data_.size());
  if (!s.ok()) {
    step_error_ = s;
    return;
  }
  offset = 0;
  for (int p = 0; p < count; ++p) {
    const size_t n = size_of(p);
    if ((p < begin || p >= end) && n > 0) {
      KeptBuffer& k = kept_[p];
      k.image.Reset(static_cast<int>(shared_shapes_[3 * p]),
                    static_cast<int>(shared_shapes_[3 * p + 1]),
                    static_cast<int>(shared_shapes_[3 * p + 2]));
      std::copy(shared_data_.data() + offset, shared_data_.data() + offset + n, k.image.data());
      k.view = views[p].view;
    }
    offset += n;
  }
}

const Image* BranchTrainer::StepBuffer(int position, int view) const {
  if (position < 0 || position >= static_cast<int>(kept_.size())) return nullptr;
  const KeptBuffer& k = kept_[position];
  return k.view == view && view >= 0 ? &k.image : nullptr;
}

void BranchTrainer::RecordView(int position, double loss) {
  double* v = position_values_.data() + position_stride_ * position;
  v[0] = loss;
  for (int k = 0; k < kColorTransformSize; ++k) v[1 + k] = exposure_gradient_[k];
  for (size_t i = 0; i < loss_terms_.size() && 1 + kColorTransformSize + i < position_stride_; ++i)
    v[1 + kColorTransformSize + i] = loss_terms_[i].value;
}

double BranchTrainer::FinishViews(Stage stage, const BatchView* views, int count,
                                  ViewGroup* group) {
  if (group->size() > 1) {
    const Status s = group->SumDisjoint(position_values_.data(), position_values_.size());
    if (!s.ok()) step_error_ = s;
  }
  double loss = 0;
  for (int p = 0; p < count; ++p) loss += position_values_[position_stride_ * p];
  for (size_t i = 0; i < loss_terms_.size(); ++i) {
    double sum = 0;
    for (int p = 0; p < count; ++p)
      sum += position_values_[position_stride_ * p + 1 + kColorTransformSize + i];
    loss_terms_[i].value = sum / count;
  }
  // Each view's colour transform, in batch order, from its own rows' gradient.
  if (!ProblemFor(stage).exposure_terms.empty()) {
    ProfileScope exposure_scope("exposure");
    for (int p = 0; p < count; ++p) {
      ColorTransform g;
      for (int k = 0; k < kColorTransformSize; ++k)
        g[k] = position_values_[position_stride_ * p + 1 + k];
      exposure_->Step(views[p].view, g, options_.exposure_lr, options_.exposure_prior,
                      options_.exposure_offset_prior, options_.exposure_mean_prior);
    }
  }
  return loss / count;
}

void BranchTrainer::TargetGradient(Stage stage, const RenderBuffers& at, const Targets& targets,
                                   TargetGradients* gradient) const {
  ProblemFor(stage).problem.EvaluateTargetGradient(branch_, at, targets, gradient);
}

std::string BranchTrainer::OptimizeAndControlDensity(const std::vector<float>* statistics,
                                                     int views,
                                                     const std::vector<ParamBlock>& gradients,
                                                     int it) {
  // The strategy's statistics and regulariser gradient (method.md 1.10: view-averaged screen
  // gradients while densifying), the Adam step, then the strategy's row operations.
  const Adam::LearningRates rates = RatesAt(it);
  DensityStep step;
  step.iteration = it;
  step.views = views;
  step.statistics = statistics;
  // Sized first: a rate function fills the list it is given (as Adam hands it one per block).
  position_rates_.assign(3, 0.0f);
  rates("means", 3, &position_rates_);
  step.position_lr = position_rates_[0];
  PrimitiveRows& rows = *rows_;
  {
    ProfileScope scope("density control");
    const double regulariser = density_->BeforeStep(step, rows, gradients);
    SetLastTerms(regulariser);
  }
  std::string nonfinite;
  {
    ProfileScope scope("adam");
    nonfinite = adam_.Step(rows.blocks(), gradients, rates);
  }
  if (!nonfinite.empty()) return nonfinite;  // the run stops: no density decisions on bad data
  ProfileScope scope("density control");
  density_->AfterStep(step, &rows, rng_);
  return "";
}

void BranchTrainer::Save(BinaryWriter* w) const {
  w->Write<int32_t>(summary_.warmup_iterations);
  w->Write<uint8_t>(summary_.auto_stopped ? 1 : 0);
  w->Write<double>(summary_.final_loss);
  WriteVector(w, auto_stop_.window());
  SaveModel(w);
  WriteAdamState(w, adam_);
  density_->Save(w);
  if (environment_ != nullptr) environment_->Save(w);
  w->Write<uint32_t>(static_cast<uint32_t>(kept_.size()));
  for (const KeptBuffer& k : kept_) {
    w->Write<int32_t>(k.view);
    for (int d : {k.image.width(), k.image.height(), k.image.channels()}) w->Write<int32_t>(d);
    WriteVector(w, std::vector<float>(k.image.data(), k.image.data() + k.image.size()));
  }
}

Status BranchTrainer::Read(BinaryReader* r) {
  Pending p;
  uint8_t stopped = 0;
  MGSR_RETURN_IF_ERROR(r->Read(&p.summary.warmup_iterations));
  MGSR_RETURN_IF_ERROR(r->Read(&stopped));
  MGSR_RETURN_IF_ERROR(r->Read(&p.summary.final_loss));
  p.summary.auto_stopped = stopped != 0;
  MGSR_RETURN_IF_ERROR(ReadVector(r, &p.window));
  if (!AllFinite(p.window))
    return Status::Error(r->path() + ": corrupt checkpoint (NaN in the " + name() +
                         " loss window)");
  if (p.summary.warmup_iterations < 0)
    return Status::Error(r->path() + ": corrupt checkpoint (" + name() + " iteration count)");
  MGSR_RETURN_IF_ERROR(ReadModel(r));
  MGSR_RETURN_IF_ERROR(ReadAdamState(r, &p.adam));
  MGSR_RETURN_IF_ERROR(density_->Read(r));
  if (environment_ != nullptr) MGSR_RETURN_IF_ERROR(environment_->Read(r));
  uint32_t kept = 0;
  MGSR_RETURN_IF_ERROR(r->Read(&kept));
  if (kept > kMaxKeptBuffers)
    return Status::Error(r->path() + ": corrupt checkpoint (" + name() + " kept buffers)");
  p.kept.resize(kept);
  for (KeptBuffer& k : p.kept) {
    int32_t view = 0, width = 0, height = 0, channels = 0;
    for (int32_t* x : {&view, &width, &height, &channels}) MGSR_RETURN_IF_ERROR(r->Read(x));
    std::vector<float> data;
    MGSR_RETURN_IF_ERROR(ReadVector(r, &data));
    if (view < -1 || width < 0 || height < 0 || channels < 0 ||
        data.size() != static_cast<size_t>(width) * height * channels || !AllFinite(data))
      return Status::Error(r->path() + ": corrupt checkpoint (" + name() + " kept buffer)");
    k.view = view;
    k.image = Image(width, height, channels);
    std::copy(data.begin(), data.end(), k.image.data());
  }
  pending_ = std::move(p);
  return Status::Ok();
}

void BranchTrainer::CommitRead() {
  CommitModel();
  adam_ = std::move(pending_.adam);
  density_->CommitRead();
  if (environment_ != nullptr) environment_->CommitRead();
  auto_stop_.set_window(pending_.window);
  summary_ = pending_.summary;
  kept_ = std::move(pending_.kept);
  pending_ = Pending();
}

}  // namespace mgsr
