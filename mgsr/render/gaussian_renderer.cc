#include "mgsr/render/gaussian_renderer.h"

#include <glog/logging.h>

#include "mgsr/core/profiler.h"
#include "mgsr/render/raster_scratch.h"

namespace mgsr {

GaussianRenderer::GaussianRenderer() : scratch_(std::make_unique<RasterScratch>()) {}
GaussianRenderer::~GaussianRenderer() = default;
GaussianRenderer::GaussianRenderer(GaussianRenderer&&) noexcept = default;
GaussianRenderer& GaussianRenderer::operator=(GaussianRenderer&&) noexcept = default;

void GaussianRenderer::Forward(const GaussianModel& model, const GaussianRenderOptions& options,
                               GaussianRender* out) {
  {
    ProfileScope scope("projection & SH");
    ProjectGaussians(model, options.camera, options.sh_degree, options.reflection, &projected_);
  }
  {
    ProfileScope scope("binning");
    BinPrimitives(projected_.rects, projected_.depth.data(), options.camera.width,
                  options.camera.height, &bins_, projected_.shapes.data(), 1);
  }
  ProfileScope scope("raster forward");
  RasterizeGaussians(projected_, bins_, options, out, scratch_.get());
}

void GaussianRenderer::Backward(const GaussianModel& model, const GaussianRenderOptions& options,
                                const GaussianRender& render, const GaussianRenderGrad& grad,
                                GaussianGradients* grads) {
  CHECK_EQ(projected_.size(), model.size()) << "Backward without a matching Forward";
  {
    ProfileScope scope("raster backward");
    RasterizeGaussiansBackward(projected_, bins_, options, render, grad, &d_projected_,
                               scratch_.get());
  }
  ProfileScope scope("projection & SH backward");
  grads->ResizeForBackward(model);
  ProjectGaussiansBackward(model, options.camera, options.sh_degree, options.reflection, projected_,
                           d_projected_, grads);
}

}  // namespace mgsr
