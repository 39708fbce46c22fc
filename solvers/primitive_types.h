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
#include "solvers/primitive_rows.h"

namespace mgsr {

// What both types share: the screen radii of their renderer's last projection.
template <typename ModelT, typename RendererT>
struct ProjectedPrimitive {
  using Model = ModelT;
  using Renderer = RendererT;
  static const std::vector<float>& Radii(const Renderer& renderer) {
    return renderer.projected().radius;
  }
};

struct SurfelPrimitive : ProjectedPrimitive<SurfelModel, SurfelRenderer> {
  using Render = SurfelRender;
  using RenderOptions = SurfelRenderOptions;
  using RenderGrad = SurfelRenderGrad;
  using Gradients = SurfelGradients;
  static constexpr Branch kBranch = Branch::kSurfels2D;
  static constexpr bool kLearntBackground = true;
  static void BackgroundGradient(const Render& r, const RenderGrad& g, Image* d_background) {
    SurfelBackgroundGradient(r, g, d_background);
  }
  // Flat disks: two scale axes; the opacity reset caps the opacity at 0.01.
  static PrimitiveLayout Layout();
  // Each block's learning rate by kind (method.md 1.8).
  static void LearningRates(const RateSchedule& s, const std::string& block, int width,
                            std::vector<float>* rates);

  static RenderBuffers Buffers(const Camera& camera, const Render& r);
  static void TakeGradients(RenderGradients* from, RenderGrad* to);
  // Renders skip the distortion where nothing reads it (SurfelRenderOptions::distortion).
  static void SkipUnread(BufferSet read, RenderOptions* o) {
    o->distortion = (read & BufferBit(Buffer::kDistortion)) != 0;
  }
  // Whether a render with options `have` gives every buffer one with `want` gives.
  static bool Provides(const RenderOptions& have, const RenderOptions& want) {
    return have.distortion || !want.distortion;
  }
};

struct GaussianPrimitive : ProjectedPrimitive<GaussianModel, GaussianRenderer> {
  using Render = GaussianRender;
  using RenderOptions = GaussianRenderOptions;
  using RenderGrad = GaussianRenderGrad;
  using Gradients = GaussianGradients;
  static constexpr Branch kBranch = Branch::kGaussians3D;
  static constexpr bool kLearntBackground = true;
  static void BackgroundGradient(const Render& r, const RenderGrad& g, Image* d_background) {
    GaussianBackgroundGradient(r, g, d_background);
  }
  // Three scale axes; the reflected opacity follows the primitive's; the opacity reset caps both
  // opacities at 0.01 and beta at 0.1 (method.md 1.10).
  static PrimitiveLayout Layout();
  // Each block's learning rate by kind; the reflected layer's blocks freeze without reflection.
  static void LearningRates(const RateSchedule& s, const std::string& block, int width,
                            std::vector<float>* rates);

  static RenderBuffers Buffers(const Camera& camera, const Render& r);
  static void TakeGradients(RenderGradients* from, RenderGrad* to);
};

using SurfelTrainer = PrimitiveTrainer<SurfelPrimitive>;
using GaussianTrainer = PrimitiveTrainer<GaussianPrimitive>;

}  // namespace mgsr
