#include "solvers/density_reference.h"

#include "mgsr/render/project_gaussians.h"
#include "solvers/checkpoint_io.h"

namespace mgsr {

double ReferenceDensity::BeforeStep(const DensityStep& step, const PrimitiveRows& rows,
                                    const std::vector<ParamBlock>& /*gradients*/) {
  // Statistics start afresh whenever the rows changed under them (a stage's pruning, a resume).
  if (stats_.grad_sum.size() != rows.size()) stats_.Reset(rows.size());
  if (step.iteration >= context_.schedule.densify_until) return 0;
  ScreenGradientNorms(*step.mean2d, step.camera->width, step.camera->height, &norms_);
  stats_.Accumulate(norms_, *step.radii);
  return 0;
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
