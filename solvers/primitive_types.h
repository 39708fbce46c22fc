// The two primitive types MGSR trains, described for PrimitiveTrainer (solvers/branch_trainer.h):
// 2DGS surfels (the geometry branch) and 3D Gaussians with a reflected layer (the appearance
// branch). Each says which buffers its render gives the loss terms, how the loss's gradients reach
// its renderer, and which density control it uses.
#pragma once

#include <vector>

#include "mgsr/loss/render_buffers.h"
#include "mgsr/render/gaussian_renderer.h"
#include "mgsr/render/surfel_renderer.h"
#include "solvers/branch_trainer.h"
#include "solvers/density_control.h"

namespace mgsr {

// What both types share: the screen radii of their renderer's last projection, and density control
// and opacity resets from solvers/density_control.h.
template <typename ModelT, typename RendererT>
struct DensityControlledPrimitive {
  using Model = ModelT;
  using Renderer = RendererT;
  static const std::vector<float>& Radii(const Renderer& renderer) {
    return renderer.projected().radius;
  }
  static DensifyResult DensifyAndPrune(Model* model, Adam* adam, DensityStats* stats,
                                       const DensityOptions& options, double extent,
                                       bool prune_large, Rng* rng) {
    return mgsr::DensifyAndPrune(model, adam, stats, options, extent, prune_large, rng);
  }
  static void ResetOpacity(Model* model, Adam* adam) { mgsr::ResetOpacity(model, adam); }
};

struct SurfelPrimitive : DensityControlledPrimitive<SurfelModel, SurfelRenderer> {
  using Render = SurfelRender;
  using RenderOptions = SurfelRenderOptions;
  using RenderGrad = SurfelRenderGrad;
  using Gradients = SurfelGradients;
  static constexpr Branch kBranch = Branch::kSurfels2D;

  static RenderBuffers Buffers(const Camera& camera, const Render& r);
  static void TakeGradients(RenderGradients* from, RenderGrad* to);
};

struct GaussianPrimitive : DensityControlledPrimitive<GaussianModel, GaussianRenderer> {
  using Render = GaussianRender;
  using RenderOptions = GaussianRenderOptions;
  using RenderGrad = GaussianRenderGrad;
  using Gradients = GaussianGradients;
  static constexpr Branch kBranch = Branch::kGaussians3D;

  static RenderBuffers Buffers(const Camera& camera, const Render& r);
  static void TakeGradients(RenderGradients* from, RenderGrad* to);
};

using SurfelTrainer = PrimitiveTrainer<SurfelPrimitive>;
using GaussianTrainer = PrimitiveTrainer<GaussianPrimitive>;

}  // namespace mgsr
