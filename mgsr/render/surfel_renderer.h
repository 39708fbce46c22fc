// SurfelRenderer: the 2DGS branch's render, forward and backward, stage by stage:
//   ProjectSurfels -> BinPrimitives -> RasterizeSurfels                (Forward)
//   RasterizeSurfelsBackward -> ProjectSurfelsBackward                 (Backward)
// It owns the intermediate buffers; Backward must follow the Forward of the same model and options.
#pragma once

#include <memory>

#include "mgsr/model/surfel_model.h"
#include "mgsr/render/project_surfels.h"
#include "mgsr/render/rasterize_surfels.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr {

class SurfelRenderer {
 public:
  // The pixel loops' scratch holds vectors whose layout depends on the instruction set the render
  // stages are compiled for: it stays behind a pointer, out of this (installed) header.
  SurfelRenderer();
  ~SurfelRenderer();
  SurfelRenderer(SurfelRenderer&&) noexcept;
  SurfelRenderer& operator=(SurfelRenderer&&) noexcept;

  void Forward(const SurfelModel& model, const SurfelRenderOptions& options, SurfelRender* out);
  void Backward(const SurfelModel& model, const SurfelRenderOptions& options,
                const SurfelRender& render, const SurfelRenderGrad& grad, SurfelGradients* grads);

  const ProjectedSurfels& projected() const { return projected_; }
  const TileBins& bins() const { return bins_; }

 private:
  ProjectedSurfels projected_;
  TileBins bins_;
  ProjectedSurfelsGrad d_projected_;
  std::unique_ptr<RasterScratch> scratch_;
};

}  // namespace mgsr
