#include "solvers/primitive_types.h"

#include <utility>

namespace mgsr {
namespace {

// Moves the gradient image of `b` into `to`, the storage `to` had going back to `g` (empty), so
// buffers kept across steps trade storage instead of allocating.
void Take(RenderGradients* g, Buffer b, Image* to) {
  Image& from = g->images[static_cast<int>(b)];
  to->swap(from);
  from.Clear();
}

}  // namespace

void SurfelPrimitive::LearningRates(const RateSchedule& s, const std::string& block, int width,
                                    std::vector<float>* rates) {
  static constexpr BlockRate kTable[] = {{"means", RateKind::kPosition},
                                         {"log_scales", RateKind::kScale},
                                         {"quats", RateKind::kRotation},
                                         {"opacity_logits", RateKind::kOpacity},
                                         {"sh", RateKind::kColor}};
  TableRates(kTable, "the surfel primitive", s, block, width, rates);
}

void GaussianPrimitive::LearningRates(const RateSchedule& s, const std::string& block, int width,
                                      std::vector<float>* rates) {
  static constexpr BlockRate kTable[] = {{"means", RateKind::kPosition},
                                         {"log_scales", RateKind::kScale},
                                         {"quats", RateKind::kRotation},
                                         {"opacity_logits", RateKind::kOpacity},
                                         {"sh", RateKind::kColor},
                                         {"ref_sh", RateKind::kReflectedColor},
                                         {"ref_opacity_logits", RateKind::kReflectedOpacity},
                                         {"beta_logits", RateKind::kReflectedOpacity}};
  TableRates(kTable, "the Gaussian primitive", s, block, width, rates);
}

PrimitiveLayout SurfelPrimitive::Layout() {
  PrimitiveLayout l;
  l.scale_axes = 2;
  return l;
}

PrimitiveLayout GaussianPrimitive::Layout() {
  PrimitiveLayout l;
  l.scale_axes = 3;
  l.opacity_blocks = {"opacity_logits", "ref_opacity_logits"};
  l.opacity_reset_caps = {
      {"opacity_logits", 0.01f}, {"ref_opacity_logits", 0.01f}, {"beta_logits", 0.1f}};
  return l;
}

RenderBuffers SurfelPrimitive::Buffers(const Camera& camera, const Render& r) {
  RenderBuffers in;
  in.camera = &camera;
  in.Set(Buffer::kColor, &r.color);
  in.Set(Buffer::kDepth, &r.depth);
  in.Set(Buffer::kAlpha, &r.alpha);
  in.Set(Buffer::kNormal, &r.normal_world);
  in.Set(Buffer::kMedianDepth, &r.median_depth);
  in.Set(Buffer::kDistortion, &r.distortion);
  return in;
}

void SurfelPrimitive::TakeGradients(RenderGradients* g, RenderGrad* out) {
  Take(g, Buffer::kColor, &out->color);
  Take(g, Buffer::kDepth, &out->depth);
  Take(g, Buffer::kAlpha, &out->alpha);
  Take(g, Buffer::kNormal, &out->normal_world);
  Take(g, Buffer::kMedianDepth, &out->median_depth);
  Take(g, Buffer::kDistortion, &out->distortion);
}

RenderBuffers GaussianPrimitive::Buffers(const Camera& camera, const Render& r) {
  RenderBuffers in;
  in.camera = &camera;
  in.Set(Buffer::kColor, &r.color);
  in.Set(Buffer::kTransmitted, &r.tran);
  in.Set(Buffer::kReflected, &r.ref);
  in.Set(Buffer::kWeight, &r.weight);
  in.Set(Buffer::kDepth, &r.depth);
  in.Set(Buffer::kAlpha, &r.alpha);
  return in;
}

void GaussianPrimitive::TakeGradients(RenderGradients* g, RenderGrad* out) {
  Take(g, Buffer::kColor, &out->color);
  Take(g, Buffer::kTransmitted, &out->tran);
  Take(g, Buffer::kReflected, &out->ref);
  Take(g, Buffer::kWeight, &out->weight);
  Take(g, Buffer::kDepth, &out->depth);
  Take(g, Buffer::kAlpha, &out->alpha);
}

}  // namespace mgsr
