#include "solvers/loss_table.h"

#include <cmath>
#include <set>

#include "mgsr/io/file_util.h"
#include "mgsr/loss/loss_registry.h"
#include "solvers/primitive_prior.h"
#include "solvers/solver_options.h"

namespace mgsr {
namespace {

nlohmann::json RenderConfig(const char* target, double lambda) {
  return {{"buffer", "color"}, {"target", target}, {"lambda", lambda}};
}

nlohmann::json TvConfig(const char* buffer, const char* guide, bool on_geometry = false,
                        double disparity_scale = 0) {
  nlohmann::json c = {{"buffer", buffer}, {"guide", guide}};
  if (on_geometry) c["on_geometry"] = true;
  if (disparity_scale > 0) c["disparity_scale"] = disparity_scale;
  return c;
}

LossSpec Row(Branch branch, Stage stage, const char* name, const char* term, nlohmann::json config,
             double weight, int first_iteration = 0, bool exposure = false) {
  LossSpec s;
  s.branch = branch;
  s.stage = stage;
  s.name = name;
  s.term = term;
  s.config = std::move(config);
  s.weight = weight;
  s.first_iteration = first_iteration;
  s.exposure = exposure;
  return s;
}

Status ParseBranch(const nlohmann::json& v, Branch* out) {
  const std::string s = v.is_string() ? v.get<std::string>() : "";
  if (s == "2d" || s == "2dgs") {
    *out = Branch::kSurfels2D;
  } else if (s == "3d" || s == "3dgs") {
    *out = Branch::kGaussians3D;
  } else {
    return Status::Error("\"branch\" must be \"2d\" or \"3d\"");
  }
  return Status::Ok();
}

// "warmup", "mutual" or "both".
Status ParseStages(const nlohmann::json& v, std::vector<Stage>* out) {
  const std::string s = v.is_string() ? v.get<std::string>() : "";
  if (s == "warmup") {
    *out = {Stage::kWarmup};
  } else if (s == "mutual") {
    *out = {Stage::kMutual};
  } else if (s == "both") {
    *out = {Stage::kWarmup, Stage::kMutual};
  } else {
    return Status::Error("\"stage\" must be \"warmup\", \"mutual\" or \"both\"");
  }
  return Status::Ok();
}

// Copies the fields a config row gives into `spec` (identity fields excepted).
Status MergeRow(const nlohmann::json& row, LossSpec* spec) {
  if (row.contains("term")) {
    if (!row["term"].is_string()) return Status::Error("\"term\" must be a string");
    spec->term = row["term"].get<std::string>();
  }
  if (row.contains("config")) {
    if (!row["config"].is_object()) return Status::Error("\"config\" must be an object");
    spec->config = row["config"];
  }
  if (row.contains("weight")) {
    if (!row["weight"].is_number()) return Status::Error("\"weight\" must be a number");
    spec->weight = row["weight"].get<double>();
  }
  if (row.contains("first_iteration")) {
    if (!row["first_iteration"].is_number_integer())
      return Status::Error("\"first_iteration\" must be an integer");
    spec->first_iteration = row["first_iteration"].get<int>();
  }
  if (row.contains("exposure")) {
    if (!row["exposure"].is_boolean()) return Status::Error("\"exposure\" must be true or false");
    spec->exposure = row["exposure"].get<bool>();
  }
  return Status::Ok();
}

Status ApplyRow(const nlohmann::json& row, std::vector<LossSpec>* table) {
  if (!row.is_object()) return Status::Error("a row must be an object");
  static const std::set<std::string> known = {
      "branch", "stage", "name", "term", "config", "weight", "first_iteration", "exposure"};
  for (const auto& [key, value] : row.items()) {
    if (known.count(key) == 0) return Status::Error("unknown key \"" + key + "\"");
  }
  for (const char* key : {"branch", "stage", "name"}) {
    if (!row.contains(key)) return Status::Error(std::string("missing \"") + key + "\"");
  }
  if (!row["name"].is_string() || row["name"].get<std::string>().empty())
    return Status::Error("\"name\" must be a non-empty string");
  Branch branch = Branch::kSurfels2D;
  std::vector<Stage> stages;
  MGSR_RETURN_IF_ERROR(ParseBranch(row["branch"], &branch));
  MGSR_RETURN_IF_ERROR(ParseStages(row["stage"], &stages));
  const std::string name = row["name"].get<std::string>();
  for (Stage stage : stages) {
    LossSpec* existing = nullptr;
    for (LossSpec& s : *table) {
      if (s.branch == branch && s.stage == stage && s.name == name) existing = &s;
    }
    if (existing != nullptr) {
      MGSR_RETURN_IF_ERROR(MergeRow(row, existing));
      continue;
    }
    if (!row.contains("term") || !row.contains("weight"))
      return Status::Error("a new row needs \"term\" and \"weight\"");
    LossSpec spec;
    spec.branch = branch;
    spec.stage = stage;
    spec.name = name;
    MGSR_RETURN_IF_ERROR(MergeRow(row, &spec));
    table->push_back(std::move(spec));
  }
  return Status::Ok();
}

double MutualNormalWeight(const SolverOptions& o) {
  return o.lambda_normal_mutual >= 0 ? o.lambda_normal_mutual : o.lambda_normal;
}

// The normal consistency's config: empty at the defaults, so the table reads as before.
nlohmann::json NormalConfig(const SolverOptions& o) {
  nlohmann::json c = nlohmann::json::object();
  if (!o.normal_depth_gradient) c["depth_gradient"] = false;
  if (o.normal_edge_weight > 0) c["edge_weight"] = o.normal_edge_weight;
  if (o.normal_robust_scale > 0) c["robust_scale"] = o.normal_robust_scale;
  if (o.normal_one_sided) c["one_sided"] = true;
  if (o.normal_agreement_floor < 1) c["agreement_floor"] = o.normal_agreement_floor;
  return c;
}

}  // namespace

const char* StageName(Stage stage) { return stage == Stage::kWarmup ? "warmup" : "mutual"; }

const char* BranchName(Branch branch) { return branch == Branch::kSurfels2D ? "2d" : "3d"; }

std::string LossSpecId(const LossSpec& spec) {
  return std::string(BranchName(spec.branch)) + "/" + StageName(spec.stage) + "/" + spec.name;
}

std::vector<LossSpec> PaperLossTable(const SolverOptions& o) {
  const Branch b2 = Branch::kSurfels2D, b3 = Branch::kGaussians3D;
  const Stage warm = Stage::kWarmup, mutual = Stage::kMutual;
  const double w = o.w_2d;
  const bool geo = o.tv_on_geometry;
  const double disp_s = o.tv_disparity_scale;
  // Row order is the order the gradients are summed in: keep it when editing (results are
  // reproducible bit for bit only in the same order).
  std::vector<LossSpec> table = {
      // 2DGS warm-up (method.md 1.3): render loss, edge-aware depth TV, normal consistency and
      // normal TV (from normal_from_iteration), depth distortion (from distortion_from_iteration).
      Row(b2, warm, "photo", "render", RenderConfig("image", o.lambda_l1), 1.0, 0, true),
      Row(b2, warm, "depth_tv", "tv", TvConfig("depth", "image", geo, disp_s),
          o.depth_tv_warmup_2d),
      Row(b2, warm, "normal_consistency", "normal_consistency", NormalConfig(o), o.lambda_normal,
          o.normal_from_iteration + 1),
      Row(b2, warm, "normal_tv", "tv", TvConfig("normal", "image", geo), o.lambda_normal_tv,
          o.normal_from_iteration + 1),
      Row(b2, warm, "distortion", "distortion", nlohmann::json::object(), o.lambda_distortion,
          o.distortion_from_iteration + 1),
      Row(b2, warm, "multiview_ncc", "multiview_ncc", nlohmann::json::object(),
          o.lambda_multiview_ncc, o.multiview_from_iteration + 1),
      Row(b2, warm, "multiview_depth", "multiview_depth", nlohmann::json::object(),
          o.lambda_multiview_depth, o.multiview_from_iteration + 1),
      Row(b2, warm, "mask", "mask", nlohmann::json::object(), o.MaskWarmupWeight()),
      // 2DGS mutual (method.md 1.5): the render loss against the 3DGS transmitted image and against
      // the photo, the TVs guided by the transmitted image; everything weighted by w_2d.
      Row(b2, mutual, "render_transmitted", "render", RenderConfig("transmitted", o.lambda_l1),
          w * o.mutual_transmitted_weight),
      Row(b2, mutual, "photo", "render", RenderConfig("image", o.lambda_l1),
          w * o.mutual_image_weight, 0, true),
      Row(b2, mutual, "normal_consistency", "normal_consistency", NormalConfig(o),
          w * MutualNormalWeight(o)),
      Row(b2, mutual, "normal_tv", "tv", TvConfig("normal", "transmitted", geo),
          w * o.lambda_normal_tv),
      Row(b2, mutual, "depth_tv", "tv", TvConfig("depth", "transmitted", geo, disp_s),
          w * o.depth_tv_mutual_2d),
      Row(b2, mutual, "distortion", "distortion", nlohmann::json::object(),
          w * o.lambda_distortion),
      Row(b2, mutual, "multiview_ncc", "multiview_ncc", nlohmann::json::object(),
          w * o.lambda_multiview_ncc),
      Row(b2, mutual, "multiview_depth", "multiview_depth", nlohmann::json::object(),
          w * o.lambda_multiview_depth),
      Row(b2, mutual, "mask", "mask", nlohmann::json::object(), w * o.lambda_mask),
      // 3DGS warm-up (method.md 1.4): render loss, edge-aware TV of the transmitted image and of
      // the depth.
      Row(b3, warm, "photo", "render", RenderConfig("image", o.lambda_l1), 1.0, 0, true),
      Row(b3, warm, "transmitted_tv", "tv", TvConfig("transmitted", "image"), o.transmitted_tv_3d),
      Row(b3, warm, "depth_tv", "tv", TvConfig("depth", "image", geo, disp_s), o.depth_tv_3d),
      // 3DGS mutual (method.md 1.5): render loss and the depth loss against the 2DGS depth.
      Row(b3, mutual, "photo", "render", RenderConfig("image", o.lambda_l1), o.w_3d, 0, true),
      Row(b3, mutual, "mutual_depth", "mutual_depth", {{"masked", false}}, o.w_depth),
  };
  // The surfel layer prior (solvers/surfel_layer_prior.h) on the 2DGS model, the same weight in
  // both stages (as measured: docs/geometry.md, "A layer of disks"). Its rows exist only when it
  // is on, so the default table, and the checkpoints that record it, stay as they were.
  if (o.lambda_surfel_layer > 0) {
    for (Stage stage : {warm, mutual})
      table.push_back(Row(b2, stage, "surfel_layer", "surfel_layer", nlohmann::json::object(),
                          o.lambda_surfel_layer));
  }
  return table;
}

Status CheckLossTable(const std::vector<LossSpec>& table) {
  std::set<std::string> ids;
  for (const LossSpec& s : table) {
    const std::string id = LossSpecId(s);
    if (!ids.insert(id).second) return Status::Error("loss row " + id + " appears twice");
    if (!(s.weight >= 0) || !std::isfinite(s.weight))
      return Status::Error("loss row " + id + ": the weight must be finite and >= 0");
    if (!s.config.is_object())
      return Status::Error("loss row " + id + ": config must be an object");
    // A term is a render term (LossRegistry) or a prior on the primitives (PriorRegistry).
    Status status;
    const bool created = PriorRegistry::Get().Has(s.term)
                             ? PriorRegistry::Get().Create(s.term, s.config, &status) != nullptr
                             : LossRegistry::Get().Create(s.term, s.config, &status) != nullptr;
    if (!created) return status.WithContext("loss row " + id + ": ");
  }
  return Status::Ok();
}

Status ApplyLossConfig(const nlohmann::json& config, const std::string& source,
                       std::vector<LossSpec>* table) {
  if (!config.is_object() || !config.contains("losses") || !config["losses"].is_array())
    return Status::Error(source + ": expected an object with a \"losses\" array");
  for (const auto& [key, value] : config.items()) {
    if (key != "losses" && key != "replace")
      return Status::Error(source + ": unknown key \"" + key + "\"");
  }
  std::vector<LossSpec> result = *table;
  if (config.contains("replace")) {
    if (!config["replace"].is_boolean())
      return Status::Error(source + ": \"replace\" must be true or false");
    if (config["replace"].get<bool>()) result.clear();
  }
  const nlohmann::json& rows = config["losses"];
  for (size_t i = 0; i < rows.size(); ++i) {
    const Status s = ApplyRow(rows[i], &result);
    if (!s.ok()) return s.WithContext(source + ": losses[" + std::to_string(i) + "]: ");
  }
  const Status s = CheckLossTable(result);
  if (!s.ok()) return s.WithContext(source + ": ");
  *table = std::move(result);
  return Status::Ok();
}

Status ApplyLossConfigFile(const std::string& path, std::vector<LossSpec>* table) {
  std::string text;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &text));
  const nlohmann::json config = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (config.is_discarded()) return Status::Error(path + ": not valid JSON");
  return ApplyLossConfig(config, path, table);
}

nlohmann::json LossSpecToJson(const LossSpec& s) {
  return {{"branch", BranchName(s.branch)},
          {"stage", StageName(s.stage)},
          {"name", s.name},
          {"term", s.term},
          {"config", s.config},
          {"weight", s.weight},
          {"first_iteration", s.first_iteration},
          {"exposure", s.exposure}};
}

nlohmann::json LossTableToJson(const std::vector<LossSpec>& table) {
  nlohmann::json rows = nlohmann::json::array();
  for (const LossSpec& s : table) rows.push_back(LossSpecToJson(s));
  return {{"replace", true}, {"losses", rows}};
}

}  // namespace mgsr
