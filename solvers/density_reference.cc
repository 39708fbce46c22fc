#include "solvers/density_reference.h"

#include "mgsr/render/project_gaussians.h"
#include "solvers/checkpoint_io.h"

namespace mgsr {

double ReferenceDensity::BeforeStep(const DensityStep& step, const PrimitiveRows& rows,
                                    const std::vector<ParamBlock>& /*gradients*/) {
  // Statistics start afresh whenever the rows changed under them (a stage's pruning, a resume).
  if (stats_.grad_sum.size() != rows.size()) stats_.Reset(rows.size());
  if (step.statistics == nullptr) return 0;  // not densifying any more
  stats_.AccumulateViews(*step.statistics);
  return 0;
}

void ReferenceDensity::ViewStatistics(const DensityView& view, float* out) {
  ScreenGradientNorms(*view.mean2d, view.camera->width, view.camera->height, &norms_);
  const std::vector<float>& radii = *view.radii;
  for (size_t i = 0; i < radii.size(); ++i) {
    const bool drawn = radii[i] > 0;
    out[2 * i] = drawn ? norms_[i] : 0.0f;
    out[2 * i + 1] = drawn ? 1.0f : 0.0f;
  }
}

DensifyResult ReferenceDensity::AfterStep(const DensityStep& step, PrimitiveRows* rows, Rng* rng) {
  const BranchSchedule& s = context_.schedule;
  const int it = step.iteration;
  DensifyResult result;
  if (it > s.densify_from && it < s.densify_until && it % s.densify_interval == 0) {
    if (stats_.grad_sum.size() != rows->size()) stats_.Reset(rows->size());
    DensityOptions d = context_.density;
    d.min_opacity = s.min_opacity;
    result = DensifyAndPrune(rows, &stats_, d, context_.extent, it > s.opacity_reset_interval, rng);
  }
  if (it < s.densify_until && it % s.opacity_reset_interval == 0) rows->ResetOpacity();
  return result;
}

void ReferenceDensity::Save(BinaryWriter* w) const {
  WriteVector(w, stats_.grad_sum);
  WriteVector(w, stats_.count);
}

Status ReferenceDensity::Read(BinaryReader* r) {
  DensityStats p;
  MGSR_RETURN_IF_ERROR(ReadVector(r, &p.grad_sum));
  MGSR_RETURN_IF_ERROR(ReadVector(r, &p.count));
  if (p.grad_sum.size() != p.count.size())
    return Status::Error(r->path() + ": corrupt checkpoint (density statistics differ in size)");
  pending_ = std::move(p);
  return Status::Ok();
}

void ReferenceDensity::CommitRead() {
  stats_ = std::move(pending_);
  pending_ = DensityStats();
}

}  // namespace mgsr
