// The "reference" density strategy (method.md 1.10, the authors' schedule): screen-gradient
// statistics while densifying, clone / split / prune every densify_interval iterations, opacity
// resets, the branch's budget as a cap (solvers/density_control.h has the row operations).
#pragma once

#include "solvers/density_control.h"
#include "solvers/density_strategy.h"

namespace mgsr {

class ReferenceDensity : public DensityStrategy {
 public:
  explicit ReferenceDensity(const DensityContext& context) : context_(context) {}

  // Per view: the NDC screen-gradient norm of every primitive drawn (radius > 0) and 1 for it
  // being drawn, while densifying.
  int ViewStatisticsWidth(int iteration) const override {
    return iteration < context_.schedule.densify_until ? 2 : 0;
  }
  void ViewStatistics(const DensityView& view, float* out) override;
  double BeforeStep(const DensityStep& step, const PrimitiveRows& rows,
                    const std::vector<ParamBlock>& gradients) override;
  DensifyResult AfterStep(const DensityStep& step, PrimitiveRows* rows, Rng* rng) override;
  void Save(BinaryWriter* w) const override;
  Status Read(BinaryReader* r) override;
  void CommitRead() override;

  const DensityStats& stats() const { return stats_; }

 private:
  std::vector<float> norms_;  // ViewStatistics' scratch
  const DensityContext context_;
  DensityStats stats_, pending_;
};

}  // namespace mgsr
