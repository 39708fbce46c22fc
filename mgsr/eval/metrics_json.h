// JSON forms of the geometry metrics, one shape for metrics.json, mgsr_eval and the harness.
#pragma once

#include <nlohmann/json.hpp>

#include "mgsr/eval/depth_error.h"
#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/eval/normal_error.h"

namespace mgsr {

// nc, cd, accuracy, completeness (null when infinite), signed offsets, fraction inside, the
// headline F-score and every F-score threshold.
nlohmann::json MeshMetricsToJson(const MeshMetrics& m);
nlohmann::json DepthErrorToJson(const DepthErrorStats& s);
nlohmann::json NormalErrorToJson(const NormalErrorStats& s);

}  // namespace mgsr
