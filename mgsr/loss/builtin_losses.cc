// The registration lines of the built-in loss terms: one per term.
#include <cmath>

#include "mgsr/loss/dssim_loss.h"
#include "mgsr/loss/edge_aware_tv_loss.h"
#include "mgsr/loss/exposure_compensation.h"
#include "mgsr/loss/l1_loss.h"
#include "mgsr/loss/loss_registry.h"
#include "mgsr/loss/mask_loss.h"
#include "mgsr/loss/multiview_depth_loss.h"
#include "mgsr/loss/multiview_ncc_loss.h"
#include "mgsr/loss/mutual_depth_loss.h"
#include "mgsr/loss/normal_consistency_loss.h"
#include "mgsr/loss/render_loss.h"

namespace mgsr {
namespace {

Status ParseTarget(const nlohmann::json& c, const char* key, TargetKind* out) {
  *out = TargetKind::kImage;
  if (!c.contains(key)) return Status::Ok();
  const std::string v = c[key].is_string() ? c[key].get<std::string>() : "";
  if (v == "image")
    *out = TargetKind::kImage;
  else if (v == "transmitted")
    *out = TargetKind::kTransmitted;
  else
    return Status::Error(std::string("'") + key + "' must be \"image\" or \"transmitted\"");
  return Status::Ok();
}

double Number(const nlohmann::json& c, const char* key, double fallback) {
  return c.contains(key) && c[key].is_number() ? c[key].get<double>() : fallback;
}

// An optional boolean: *out keeps its default when `key` is absent.
Status ParseFlag(const nlohmann::json& c, const char* key, bool* out) {
  if (!c.contains(key)) return Status::Ok();
  if (!c[key].is_boolean())
    return Status::Error(std::string("'") + key + "' must be true or false");
  *out = c[key].get<bool>();
  return Status::Ok();
}

// An optional finite weight >= 0: *out keeps its default when `key` is absent.
Status ParseWeight(const nlohmann::json& c, const char* key, double* out) {
  const double v = Number(c, key, *out);
  if (!(v >= 0) || !std::isfinite(v)) {
    return Status::Error(std::string("'") + key + "' must be finite and >= 0");
  }
  *out = v;
  return Status::Ok();
}

// Factory for the (buffer, target) photometric terms.
template <typename Term>
LossRegistry::Factory Photometric(Buffer default_buffer) {
  return [default_buffer](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
    Buffer b;
    TargetKind t;
    *s = ParseBuffer(c, "buffer", default_buffer, &b);
    if (s->ok()) *s = ParseTarget(c, "target", &t);
    if (!s->ok()) return nullptr;
    return std::make_unique<Term>(b, t);
  };
}

}  // namespace

void RegisterBuiltinLosses(LossRegistry* r) {
  r->Register("l1", Photometric<L1Loss>(Buffer::kColor));
  r->Register("dssim", Photometric<DssimLoss>(Buffer::kColor));
  r->Register("render", [](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
    Buffer b;
    TargetKind t;
    *s = ParseBuffer(c, "buffer", Buffer::kColor, &b);
    if (s->ok()) *s = ParseTarget(c, "target", &t);
    if (!s->ok()) return nullptr;
    return std::make_unique<RenderLoss>(b, t, Number(c, "lambda", 0.8));
  });
  r->Register("mutual_render", [](const nlohmann::json& c, Status*) -> std::unique_ptr<LossTerm> {
    return std::make_unique<MutualRenderLoss>(Number(c, "transmitted_weight", 0.2),
                                              Number(c, "image_weight", 0.8),
                                              Number(c, "lambda", 0.8));
  });
  r->Register("tv", [](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
    Buffer b;
    TargetKind g;
    *s = ParseBuffer(c, "buffer", Buffer::kDepth, &b);
    if (s->ok()) *s = ParseTarget(c, "guide", &g);
    bool on_geometry = false;
    if (s->ok()) *s = ParseFlag(c, "on_geometry", &on_geometry);
    if (!s->ok()) return nullptr;
    const double disparity_scale = Number(c, "disparity_scale", 0);
    if (!(disparity_scale >= 0)) {
      *s = Status::Error("'disparity_scale' must be >= 0");
      return nullptr;
    }
    return std::make_unique<EdgeAwareTvLoss>(b, g, on_geometry, disparity_scale);
  });
  r->Register("normal_consistency",
              [](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
                NormalConsistencyOptions o;
                *s = ParseFlag(c, "depth_gradient", &o.depth_gradient);
                if (s->ok()) *s = ParseWeight(c, "edge_weight", &o.edge_weight);
                if (s->ok()) *s = ParseWeight(c, "robust_scale", &o.robust_scale);
                if (s->ok()) *s = ParseFlag(c, "one_sided", &o.one_sided);
                if (s->ok()) *s = ParseWeight(c, "agreement_floor", &o.agreement_floor);
                if (s->ok() && o.agreement_floor > 1)
                  *s = Status::Error("'agreement_floor' must be in [0, 1]");
                if (!s->ok()) return nullptr;
                return std::make_unique<NormalConsistencyLoss>(o);
              });
  r->Register("mutual_depth", [](const nlohmann::json& c, Status*) -> std::unique_ptr<LossTerm> {
    return std::make_unique<MutualDepthLoss>(c.contains("masked") && c["masked"].is_boolean() &&
                                             c["masked"].get<bool>());
  });
  // The render loss behind a fixed per-view colour transform ("transform": A row-major, then b);
  // the solver sets each view's transform itself.
  r->Register(
      "exposure_render", [](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
        ColorTransform p = IdentityColorTransform();
        if (c.contains("transform")) {
          const auto& a = c["transform"];
          if (!a.is_array() || a.size() != kColorTransformSize) {
            *s = Status::Error("'transform' must be an array of 12 numbers (A row-major, then b)");
            return nullptr;
          }
          for (int i = 0; i < kColorTransformSize; ++i) {
            if (!a[i].is_number()) {
              *s =
                  Status::Error("'transform' must be an array of 12 numbers (A row-major, then b)");
              return nullptr;
            }
            p[i] = a[i].get<double>();
          }
        }
        return std::make_unique<ExposureCompensatedLoss>(
            std::make_unique<RenderLoss>(Buffer::kColor, TargetKind::kImage,
                                         Number(c, "lambda", 0.8)),
            p);
      });
  r->Register("mask", [](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
    bool foreground = true;
    *s = ParseFlag(c, "foreground", &foreground);
    if (!s->ok()) return nullptr;
    return std::make_unique<MaskLoss>(foreground);
  });
  r->Register("distortion", [](const nlohmann::json&, Status*) -> std::unique_ptr<LossTerm> {
    return std::make_unique<DistortionLoss>();
  });
  r->Register("multiview_ncc", [](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
    MultiviewNccConfig m;
    m.patch_radius = static_cast<int>(Number(c, "patch_radius", m.patch_radius));
    m.stride = static_cast<int>(Number(c, "stride", m.stride));
    const double max_centres = Number(c, "max_centres", m.max_centres);
    m.max_centres = max_centres >= 1 && max_centres <= 1e9 ? static_cast<int>(max_centres) : 0;
    m.min_variance = Number(c, "min_variance", m.min_variance);
    m.min_alpha = Number(c, "min_alpha", m.min_alpha);
    m.max_reprojection_px = Number(c, "max_reprojection_px", m.max_reprojection_px);
    m.max_plane_offset_px = Number(c, "max_plane_offset_px", m.max_plane_offset_px);
    m.max_pair_loss = Number(c, "max_pair_loss", m.max_pair_loss);
    if (c.contains("check_occlusion")) {
      if (!c["check_occlusion"].is_boolean()) {
        *s = Status::Error("'check_occlusion' must be true or false");
        return nullptr;
      }
      m.check_occlusion = c["check_occlusion"].get<bool>();
    }
    *s = ParseFlag(c, "fit_plane", &m.fit_plane);
    if (!s->ok()) return nullptr;
    if (m.patch_radius < 1 || m.patch_radius > 10 || m.stride < 1 || m.stride > 64 ||
        m.max_centres < 1 || !(m.min_variance >= 0) || !(m.max_reprojection_px > 0) ||
        !(m.max_pair_loss > 0)) {
      *s = Status::Error(
          "multiview_ncc: patch_radius in [1, 10], stride in [1, 64], max_centres in [1, 1e9], "
          "min_variance >= 0, max_reprojection_px > 0, max_pair_loss > 0");
      return nullptr;
    }
    return std::make_unique<MultiviewNccLoss>(m);
  });
  r->Register("multiview_depth",
              [](const nlohmann::json& c, Status* s) -> std::unique_ptr<LossTerm> {
                MultiviewDepthConfig m;
                m.stride = static_cast<int>(Number(c, "stride", m.stride));
                m.max_error_px = Number(c, "max_error_px", m.max_error_px);
                m.min_alpha = Number(c, "min_alpha", m.min_alpha);
                if (m.stride < 1 || m.stride > 64 || !(m.max_error_px > 0)) {
                  *s = Status::Error("multiview_depth: stride in [1, 64], max_error_px > 0");
                  return nullptr;
                }
                return std::make_unique<MultiviewDepthLoss>(m);
              });
}

}  // namespace mgsr
