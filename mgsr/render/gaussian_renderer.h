// GaussianRenderer: the 3DGS branch's render, forward and backward, stage by stage:
//   ProjectGaussians -> BinPrimitives -> RasterizeGaussians            (Forward)
//   RasterizeGaussiansBackward -> ProjectGaussiansBackward             (Backward)
// It owns the intermediate buffers, so repeated calls do not allocate once warm. Backward must
// follow the Forward of the same model and options.
#pragma once

#include <memory>

#include "mgsr/model/gaussian_model.h"
#include "mgsr/render/project_gaussians.h"
#include "mgsr/render/rasterize_gaussians.h"
#include "mgsr/render/tile_binning.h"

namespace mgsr {

class GaussianRenderer {
 public:
  // The pixel loops' scratch holds vectors whose layout depends on the instruction set the render
  // stages are compiled for: it stays behind a pointer, out of this (installed) header.
  GaussianRenderer();
  ~GaussianRenderer();
  GaussianRenderer(GaussianRenderer&&) noexcept;
  GaussianRenderer& operator=(GaussianRenderer&&) noexcept;

  void Forward(const GaussianModel& model, const GaussianRenderOptions& options,
               GaussianRender* out);
  // Writes (overwrites) `grads` with d loss / d raw parameters for the upstream image gradients.
  void Backward(const GaussianModel& model, const GaussianRenderOptions& options,
                const GaussianRender& render, const GaussianRenderGrad& grad,
                GaussianGradients* grads);

  const ProjectedGaussians& projected() const { return projected_; }
  const TileBins& bins() const { return bins_; }

 private:
  ProjectedGaussians projected_;
  TileBins bins_;
  ProjectedGaussiansGrad d_projected_;
  std::unique_ptr<RasterScratch> scratch_;
};

}  // namespace mgsr
