#include "solvers/density_mcmc.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "mgsr/model/activations.h"

namespace mgsr {
namespace {

// gsplat caps the copies of one primitive per event at 51 (its binomial table); a primitive drawn
// more often than that in one event is matched as 51.
constexpr int kMaxCopies = 51;
// ActivateAddAndSum's loops over at least this many entries (a 128 px view's worth, as the loss
// kernels) run on all threads.
constexpr int64_t kParallelFrom = 16384;

// s_i = activate(x_i) and d_i += w * slope(s_i) on all threads, then the sum of the s_i in order in
// double, returned: what one loop on one thread computed, to the bit (`scratch` holds the s_i).
template <typename Activate, typename Slope>
double ActivateAddAndSum(const float* x, size_t n, float w, Activate activate, Slope slope,
                         float* d, std::vector<float>* scratch) {
  scratch->resize(n);
  float* const s = scratch->data();
  const int64_t count = static_cast<int64_t>(n);
#pragma omp parallel for schedule(static) if (count >= kParallelFrom)
  for (int64_t i = 0; i < count; ++i) {
    s[i] = activate(x[i]);
    d[i] += w * slope(s[i]);
  }
  double sum = 0;
  for (size_t i = 0; i < n; ++i) sum += s[i];
  return sum;
}

// Draws `count` rows with replacement, row i with probability weight[i] / sum (weights >= 0, at
// least one > 0): inverse transform sampling on the cumulative sums.
std::vector<int> SampleByWeight(const std::vector<double>& weight, size_t count, Rng* rng) {
  std::vector<double> cumulative(weight.size());
  double total = 0;
  for (size_t i = 0; i < weight.size(); ++i) cumulative[i] = total += weight[i];
  std::vector<int> out(count);
  for (size_t k = 0; k < count; ++k) {
    const double u = rng->Uniform() * total;
    size_t i = std::upper_bound(cumulative.begin(), cumulative.end(), u) - cumulative.begin();
    // Past the end only by rounding; step back onto a row of positive weight.
    i = std::min(i, weight.size() - 1);
    while (i > 0 && weight[i] <= 0) --i;
    out[k] = static_cast<int>(i);
  }
  return out;
}

float Logit(double p) {
  p = std::min(std::max(p, 1e-12), 1.0 - 1e-7);
  return static_cast<float>(std::log(p / (1.0 - p)));
}

}  // namespace

Status McmcOptions::FromJson(const nlohmann::json& config, McmcOptions* out) {
  McmcOptions o;
  if (!config.is_null() && !config.is_object())
    return Status::Error("the config must be a JSON object");
  if (config.is_object()) {
    for (const auto& [key, value] : config.items()) {
      float* field = key == "dead_opacity"  ? &o.dead_opacity
                     : key == "growth"      ? &o.growth
                     : key == "noise_lr"    ? &o.noise_lr
                     : key == "opacity_reg" ? &o.opacity_reg
                     : key == "scale_reg"   ? &o.scale_reg
                                            : nullptr;
      if (field == nullptr) return Status::Error("unknown key \"" + key + "\"");
      if (!value.is_number() || value.get<double>() < 0)
        return Status::Error("\"" + key + "\" must be a number >= 0");
      *field = value.get<float>();
    }
  }
  if (o.dead_opacity >= 1) return Status::Error("\"dead_opacity\" must be below 1");
  *out = o;
  return Status::Ok();
}

Relocation MomentMatchedRelocation(double opacity, int count) {
  count = std::max(1, std::min(count, kMaxCopies));
  // Paper eq. 9: N copies of opacity o' = 1 - (1 - o)^(1/N) composite to o; the scale factor
  // makes their summed footprint match the original's:
  //   s' = s o / sum_{i=1..N} sum_{k=0..i-1} C(i-1, k) (-1)^k o'^(k+1) / sqrt(k+1).
  const double o = std::min(std::max(opacity, 0.0), 1.0 - 1e-7);
  const double o_new = -std::expm1(std::log1p(-o) / count);
  double denominator = 0;
  for (int i = 1; i <= count; ++i) {
    double binomial = 1;  // C(i-1, k)
    double power = o_new;
    for (int k = 0; k < i; ++k) {
      denominator += (k % 2 == 0 ? 1 : -1) * binomial * power / std::sqrt(k + 1.0);
      binomial = binomial * (i - 1 - k) / (k + 1);
      power *= o_new;
    }
  }
  Relocation r;
  r.opacity = o_new;
  r.scale_factor = denominator > 0 ? o / denominator : 1.0;
  return r;
}

std::vector<float> McmcDensity::Opacities(const PrimitiveRows& rows) const {
  std::vector<float> opacity(rows.size(), 0.0f);
  for (const std::string& name : rows.layout().opacity_blocks) {
    const float* logits = rows.Block(name);
    if (logits == nullptr) continue;
    for (size_t i = 0; i < rows.size(); ++i) opacity[i] = std::max(opacity[i], Sigmoid(logits[i]));
  }
  return opacity;
}

void McmcDensity::Begin(PrimitiveRows* rows, Rng* rng) {
  const size_t cap = context_.density.max_primitives;
  const BranchSchedule& s = context_.schedule;
  int events = 0;
  for (int it = s.densify_from + 1; it < s.densify_until; ++it)
    events += it % s.densify_interval == 0;
  if (rows->size() > 0 && rows->size() < cap && events > 0) {
    const double half = std::max(1.0, 0.5 * events);
    const double needed = std::pow(static_cast<double>(cap) / rows->size(), 1.0 / half) - 1.0;
    growth_ = std::max(options_.growth, static_cast<float>(needed));
  }
  if (cap == 0 || rows->size() <= cap) return;
  // A uniform subset of `cap` rows, in their order (a partial Fisher-Yates shuffle).
  std::vector<size_t> order(rows->size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  for (size_t i = 0; i < cap; ++i)
    std::swap(order[i], order[i + rng->UniformInt(order.size() - i)]);
  std::vector<uint8_t> keep(rows->size(), 0);
  for (size_t i = 0; i < cap; ++i) keep[order[i]] = 1;
  rows->KeepRows(keep);
}

void McmcDensity::Save(BinaryWriter* w) const { w->Write<float>(growth_); }

Status McmcDensity::Read(BinaryReader* r) {
  float g = 0;
  MGSR_RETURN_IF_ERROR(r->Read(&g));
  if (!(g >= 0) || !std::isfinite(g))
    return Status::Error(r->path() + ": corrupt checkpoint (MCMC growth rate)");
  pending_growth_ = g;
  return Status::Ok();
}

double McmcDensity::BeforeStep(const DensityStep& step, const PrimitiveRows& rows,
                               const std::vector<ParamBlock>& gradients) {
  // opacity_reg x mean(opacity) + scale_reg x mean(scale) / extent, over the primitive's own
  // opacity and every scale axis; once per view of the step (the gradients it is added to are
  // the sum of the step's views' gradients, so its weight relative to them stays the same).
  const float views = static_cast<float>(step.views);
  const size_t n = rows.size();
  if (n == 0) return 0;
  float* d_opacity = nullptr;
  float* d_scale = nullptr;
  for (const ParamBlock& g : gradients) {
    if (g.name == "opacity_logits") d_opacity = g.data->data();
    if (g.name == "log_scales") d_scale = g.data->data();
  }
  double value = 0;
  const float* logits = rows.Block("opacity_logits");
  if (options_.opacity_reg > 0 && logits != nullptr && d_opacity != nullptr) {
    const float w = options_.opacity_reg / static_cast<float>(n) * views;
    const double sum = ActivateAddAndSum(
        logits, n, w, [](float x) { return Sigmoid(x); },
        [](float s) { return SigmoidGradFromValue(s); }, d_opacity, &activated_);
    value += options_.opacity_reg * sum / n * views;
  }
  const float* log_scales = rows.Block("log_scales");
  const int axes = rows.layout().scale_axes;
  if (options_.scale_reg > 0 && log_scales != nullptr && d_scale != nullptr && axes > 0) {
    const size_t count = n * axes;
    const float w = options_.scale_reg / static_cast<float>(count * context_.extent) * views;
    const double sum = ActivateAddAndSum(
        log_scales, count, w, [](float x) { return std::exp(x); }, [](float s) { return s; },
        d_scale, &activated_);
    value += options_.scale_reg * sum / (count * context_.extent) * views;
  }
  return value;
}

DensifyResult McmcDensity::AfterStep(const DensityStep& step, PrimitiveRows* rows, Rng* rng) {
  DensifyResult result;
  const BranchSchedule& s = context_.schedule;
  const int it = step.iteration;
  if (it > s.densify_from && it < s.densify_until && it % s.densify_interval == 0) {
    result.relocated = Relocate(rows, rng);
    result.added = Add(rows, rng);
  }
  InjectNoise(step, rows, rng);
  return result;
}

void McmcDensity::MatchMoments(const std::vector<int>& sampled, PrimitiveRows* rows) const {
  std::vector<int> copies(rows->size(), 0);
  for (int i : sampled) ++copies[i];
  const std::vector<float> opacity = Opacities(*rows);
  float* log_scales = rows->Block("log_scales");
  const int axes = rows->layout().scale_axes;
  const std::vector<std::string>& opacity_blocks = rows->layout().opacity_blocks;
  for (size_t i = 0; i < copies.size(); ++i) {
    if (copies[i] == 0) continue;
    const int count = copies[i] + 1;
    // The footprint follows the opacity the primitive is judged by; every opacity block is
    // divided among the copies by its own value.
    const Relocation r = MomentMatchedRelocation(opacity[i], count);
    double largest = 0;
    for (const std::string& name : opacity_blocks) {
      float* logits = rows->Block(name);
      if (logits == nullptr) continue;
      const double own = MomentMatchedRelocation(Sigmoid(logits[i]), count).opacity;
      largest = std::max(largest, own);
      logits[i] = Logit(own);
    }
    // Like gsplat, a copy is not born below the dead threshold: its own opacity is raised to it.
    float* own_logits = rows->Block("opacity_logits");
    if (largest < options_.dead_opacity && own_logits != nullptr)
      own_logits[i] = Logit(options_.dead_opacity);
    if (log_scales != nullptr) {
      const float shift = static_cast<float>(std::log(std::max(r.scale_factor, 1e-6)));
      for (int k = 0; k < axes; ++k) log_scales[axes * i + k] += shift;
    }
  }
}

size_t McmcDensity::Relocate(PrimitiveRows* rows, Rng* rng) const {
  const std::vector<float> opacity = Opacities(*rows);
  std::vector<int> dead;
  std::vector<double> weight(rows->size(), 0.0);
  for (size_t i = 0; i < rows->size(); ++i) {
    if (opacity[i] <= options_.dead_opacity) {
      dead.push_back(static_cast<int>(i));
    } else {
      weight[i] = opacity[i];
    }
  }
  if (dead.empty() || dead.size() == rows->size()) return 0;
  const std::vector<int> sampled = SampleByWeight(weight, dead.size(), rng);
  MatchMoments(sampled, rows);
  // The dead take the matched values of the primitive they were drawn onto; all start afresh.
  for (size_t k = 0; k < dead.size(); ++k) rows->CopyRow(sampled[k], dead[k]);
  std::vector<int> touched = sampled;
  touched.insert(touched.end(), dead.begin(), dead.end());
  rows->ZeroMoments(touched);
  return dead.size();
}

size_t McmcDensity::Add(PrimitiveRows* rows, Rng* rng) const {
  const size_t n = rows->size();
  const size_t cap = context_.density.max_primitives;
  const size_t target = std::min(cap, static_cast<size_t>(std::floor((1.0 + growth_) * n)));
  if (target <= n) return 0;
  const std::vector<float> opacity = Opacities(*rows);
  std::vector<double> weight(n);
  double total = 0;
  for (size_t i = 0; i < n; ++i) total += weight[i] = opacity[i];
  if (total <= 0) return 0;
  const std::vector<int> sampled = SampleByWeight(weight, target - n, rng);
  MatchMoments(sampled, rows);
  rows->ZeroMoments(sampled);
  rows->AppendCopies(sampled);
  return sampled.size();
}

void McmcDensity::InjectNoise(const DensityStep& step, PrimitiveRows* rows, Rng* rng) const {
  if (options_.noise_lr <= 0 || step.position_lr <= 0) return;
  float* means = rows->Block("means");
  const float* log_scales = rows->Block("log_scales");
  const float* quats = rows->Block("quats");
  const float* logits = rows->Block("opacity_logits");
  const int axes = rows->layout().scale_axes;
  if (means == nullptr || log_scales == nullptr || quats == nullptr || logits == nullptr) return;
  // Displacement = noise_lr x (position rate / extent) x (covariance / extent) x N(0, I), gated
  // by sigmoid(100 (1 - opacity - 0.995)) so only nearly transparent primitives wander. gsplat uses
  // the rate and covariance as they are on scenes normalised to extent ~1; dividing by the extent
  // keeps the step the same share of the scene at any scale.
  const double extent = context_.extent;
  const double base = options_.noise_lr * step.position_lr / (extent * extent);
  for (size_t i = 0; i < rows->size(); ++i) {
    // From logit -1.7 up (opacity 0.15) the gate below is under 3.2e-7 and the primitive is
    // skipped anyway: decided without the two exps (most primitives are this opaque).
    if (logits[i] > -1.7f) continue;
    const double gate = 1.0 / (1.0 + std::exp(-100.0 * ((1.0 - Sigmoid(logits[i])) - 0.995)));
    // Below 1e-6 the displacement is far under a float's resolution of the position: skip the
    // draws (deterministic: the decision depends only on the model).
    if (gate < 1e-6) continue;
    float R[9], q_unit[4];
    QuaternionToRotation(&quats[4 * i], R, q_unit);
    // Covariance x z = R diag(s^2) R^T z; a surfel's third axis has zero extent.
    double z[3], local[3] = {0, 0, 0};
    for (double& v : z) v = rng->Normal();
    for (int k = 0; k < axes; ++k) {
      const double rt_z = R[k] * z[0] + R[3 + k] * z[1] + R[6 + k] * z[2];  // (R^T z)_k
      local[k] = std::exp(2.0 * log_scales[axes * i + k]) * rt_z;
    }
    const double step_size = base * gate;
    for (int r = 0; r < 3; ++r) {
      means[3 * i + r] += static_cast<float>(
          step_size * (R[3 * r] * local[0] + R[3 * r + 1] * local[1] + R[3 * r + 2] * local[2]));
    }
  }
}

}  // namespace mgsr
