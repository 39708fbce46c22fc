#include "mgsr/render/surfel_renderer.h"

#include <glog/logging.h>

#include "mgsr/core/profiler.h"
#include "mgsr/render/raster_scratch.h"

namespace mgsr {

SurfelRenderer::SurfelRenderer() : scratch_(std::make_unique<RasterScratch>()) {}
SurfelRenderer::~SurfelRenderer() = default;
SurfelRenderer::SurfelRenderer(SurfelRenderer&&) noexcept = default;
SurfelRenderer& SurfelRenderer::operator=(SurfelRenderer&&) noexcept = default;

void SurfelRenderer::Forward(const SurfelModel& model, const SurfelRenderOptions& options,
                             SurfelRender* out) {
  {
    ProfileScope scope("projection & SH");
    ProjectSurfels(model, options.camera, options.sh_degree, &projected_, options.filter_sigma);
  }
  {
    ProfileScope scope("binning");
    BinPrimitives(projected_.rects, projected_.depth.data(), options.camera.width,
                  options.camera.height, &bins_, projected_.shapes.data(), 2);
  }
  ProfileScope scope("raster forward");
  RasterizeSurfels(projected_, bins_, options, out, scratch_.get());
}

void SurfelRenderer::Backward(const SurfelModel& model, const SurfelRenderOptions& options,
                              const SurfelRender& render, const SurfelRenderGrad& grad,
                              SurfelGradients* grads) {
  CHECK_EQ(projected_.size(), model.size()) << "Backward without a matching Forward";
  {
    ProfileScope scope("raster backward");
    RasterizeSurfelsBackward(projected_, bins_, options, render, grad, &d_projected_,
                             scratch_.get());
  }
  ProfileScope scope("projection & SH backward");
  grads->ResizeForBackward(model);
  ProjectSurfelsBackward(model, options.camera, options.sh_degree, projected_, d_projected_, grads);
}

}  // namespace mgsr
