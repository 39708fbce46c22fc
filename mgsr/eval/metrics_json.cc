#include "mgsr/eval/metrics_json.h"

#include <cmath>

namespace mgsr {
namespace {

nlohmann::json FiniteOrNull(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

}  // namespace

nlohmann::json MeshMetricsToJson(const MeshMetrics& m) {
  nlohmann::json j = {{"ok", m.ok},
                      {"nc", m.normal_consistency},
                      {"cd", FiniteOrNull(m.chamfer)},
                      {"accuracy", FiniteOrNull(m.accuracy)},
                      {"completeness", FiniteOrNull(m.completeness)},
                      {"signed_offset_median", m.signed_offset_median},
                      {"signed_offset_mean", m.signed_offset_mean},
                      {"signed_offset_median_from_gt", m.signed_offset_median_gt},
                      {"fraction_inside", m.fraction_inside},
                      {"precision", m.precision},
                      {"recall", m.recall},
                      {"fscore", m.fscore}};
  if (!m.ok) j["failure"] = m.failure;
  if (m.pixel_footprint > 0) {
    j["pixel_footprint"] = m.pixel_footprint;
    j["signed_offset_median_px"] = m.signed_offset_median / m.pixel_footprint;
  }
  nlohmann::json f = nlohmann::json::array();
  for (const FScore& s : m.fscores) {
    nlohmann::json e = {{"threshold", s.threshold},
                        {"precision", s.precision},
                        {"recall", s.recall},
                        {"fscore", s.fscore}};
    if (s.footprints > 0) e["footprints"] = s.footprints;
    f.push_back(e);
  }
  j["fscores"] = f;
  return j;
}

nlohmann::json DepthErrorToJson(const DepthErrorStats& s) {
  return {{"pixels", s.pixels},
          {"median", s.median},
          {"median_px", s.median_footprints},
          {"mean", s.mean},
          {"mean_abs", s.mean_abs},
          {"share_beyond_1px", s.share_beyond_footprint}};
}

nlohmann::json NormalErrorToJson(const NormalErrorStats& s) {
  return {{"pixels", s.pixels},
          {"mean_deg", s.mean_deg},
          {"median_deg", s.median_deg},
          {"share_beyond_10deg", s.share_beyond_10deg}};
}

}  // namespace mgsr
