#include "solvers/loss_table.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "solvers/solver_options.h"
#include "test_util.h"

namespace mgsr {
namespace {

const LossSpec* Find(const std::vector<LossSpec>& table, Branch b, Stage s, const std::string& n) {
  for (const LossSpec& r : table) {
    if (r.branch == b && r.stage == s && r.name == n) return &r;
  }
  return nullptr;
}

// The weight of the 2DGS row `n` of stage `s` (NaN, and a failure, when the row is missing).
double Weight2D(const std::vector<LossSpec>& table, Stage s, const std::string& n) {
  const LossSpec* r = Find(table, Branch::kSurfels2D, s, n);
  if (r == nullptr) {
    ADD_FAILURE() << "no 2DGS row " << n;
    return std::nan("");
  }
  return r->weight;
}

TEST(LossTableTest, ThePaperTableFollowsTheOptions) {
  SolverOptions o;
  o.lambda_normal = 0.7;
  o.w_2d = 0.25;
  o.normal_from_iteration = 300;
  o.lambda_mask = 0.3;
  const std::vector<LossSpec> t = PaperLossTable(o);
  ASSERT_TRUE(CheckLossTable(t).ok());
  EXPECT_EQ(t.size(), 22u);
  EXPECT_EQ(Weight2D(t, Stage::kWarmup, "mask"), 0.3);
  EXPECT_EQ(Weight2D(t, Stage::kMutual, "mask"), 0.25 * 0.3);
  // An option of its own moves its row's weights to `warmup` and `mutual`; `refused` (a negative
  // value that is not the option's "unset") is refused.
  const auto expect_own_weight = [&o](double SolverOptions::*option, double value,
                                      const std::string& row, double warmup, double mutual,
                                      double refused) {
    SCOPED_TRACE(row);
    SolverOptions own = o;
    own.*option = value;
    const std::vector<LossSpec> t_own = PaperLossTable(own);
    EXPECT_EQ(Weight2D(t_own, Stage::kWarmup, row), warmup);
    EXPECT_EQ(Weight2D(t_own, Stage::kMutual, row), mutual);
    own.*option = refused;
    EXPECT_FALSE(own.Validate().ok());
  };
  // The warm-up's own silhouette weight, when given.
  // (-1 means "unset" there, so -2 is the value refused.)
  expect_own_weight(&SolverOptions::lambda_mask_warmup, 4, "mask", 4, 0.25 * 0.3, -2);
  const LossSpec* nc = Find(t, Branch::kSurfels2D, Stage::kWarmup, "normal_consistency");
  ASSERT_NE(nc, nullptr);
  EXPECT_EQ(nc->weight, 0.7);
  EXPECT_EQ(nc->first_iteration, 301);  // on after normal_from_iteration
  const LossSpec* mnc = Find(t, Branch::kSurfels2D, Stage::kMutual, "normal_consistency");
  ASSERT_NE(mnc, nullptr);
  EXPECT_EQ(mnc->weight, 0.25 * 0.7);
  // The normal TV keeps its own weight (the reference's 0.05 unless set), not the consistency's.
  const LossSpec* ntv = Find(t, Branch::kSurfels2D, Stage::kWarmup, "normal_tv");
  ASSERT_NE(ntv, nullptr);
  EXPECT_EQ(ntv->weight, 0.05);
  EXPECT_EQ(ntv->first_iteration, 301);
  EXPECT_EQ(Weight2D(t, Stage::kMutual, "normal_tv"), 0.25 * 0.05);
  expect_own_weight(&SolverOptions::lambda_normal_tv, 0.4, "normal_tv", 0.4, 0.25 * 0.4, -1);
  SolverOptions tv = o;
  tv.lambda_normal_tv = 0.4;
  EXPECT_EQ(Weight2D(PaperLossTable(tv), Stage::kWarmup, "normal_consistency"), 0.7);
  // The photo rows sit behind the view's colour transform, the transmitted target does not.
  EXPECT_TRUE(Find(t, Branch::kGaussians3D, Stage::kMutual, "photo")->exposure);
  EXPECT_FALSE(Find(t, Branch::kSurfels2D, Stage::kMutual, "render_transmitted")->exposure);
  EXPECT_EQ(Find(t, Branch::kGaussians3D, Stage::kMutual, "mutual_depth")->weight, o.w_depth);
  // An empty SolverOptions::losses means this table; a given one is used as it is.
  EXPECT_EQ(LossTableToJson(o.LossTable()), LossTableToJson(t));
  o.losses = {t[0]};
  EXPECT_EQ(o.LossTable().size(), 1u);
}

TEST(LossTableTest, AConfigChangesRowsAddsRowsOrReplacesTheTable) {
  SolverOptions o;
  std::vector<LossSpec> t = PaperLossTable(o);
  const size_t rows = t.size();
  const nlohmann::json config = nlohmann::json::parse(R"({"losses": [
      {"branch": "2d", "stage": "warmup", "name": "normal_consistency", "weight": 0.5},
      {"branch": "3d", "stage": "both", "name": "alpha_l1", "term": "l1",
       "config": {"buffer": "alpha"}, "weight": 0.1, "first_iteration": 50}]})");
  ASSERT_TRUE(ApplyLossConfig(config, "c.json", &t).ok());
  ASSERT_EQ(t.size(), rows + 2);  // "both" is one row per stage
  const LossSpec* nc = Find(t, Branch::kSurfels2D, Stage::kWarmup, "normal_consistency");
  EXPECT_EQ(nc->weight, 0.5);
  EXPECT_EQ(nc->term, "normal_consistency");  // fields not given are kept
  EXPECT_EQ(nc->first_iteration, o.normal_from_iteration + 1);
  for (Stage s : {Stage::kWarmup, Stage::kMutual}) {
    const LossSpec* a = Find(t, Branch::kGaussians3D, s, "alpha_l1");
    ASSERT_NE(a, nullptr);
    EXPECT_EQ(a->term, "l1");
    EXPECT_EQ(a->config["buffer"], "alpha");
    EXPECT_EQ(a->first_iteration, 50);
  }
  // The table survives its own JSON form (what a checkpoint and metrics.json record).
  std::vector<LossSpec> copy = PaperLossTable(o);
  ASSERT_TRUE(ApplyLossConfig(LossTableToJson(t), "dump", &copy).ok());
  EXPECT_EQ(LossTableToJson(copy), LossTableToJson(t));
  // replace: only the given rows.
  const nlohmann::json only = nlohmann::json::parse(R"({"replace": true, "losses": [
      {"branch": "2d", "stage": "warmup", "name": "photo", "term": "render", "weight": 1}]})");
  ASSERT_TRUE(ApplyLossConfig(only, "c.json", &t).ok());
  EXPECT_EQ(t.size(), 1u);
}

TEST(LossTableTest, TheSurfelLayerPriorHasRowsOnlyWhenItIsOn) {
  SolverOptions o;
  const std::vector<LossSpec> off = PaperLossTable(o);
  EXPECT_EQ(Find(off, Branch::kSurfels2D, Stage::kWarmup, "surfel_layer"), nullptr);
  o.lambda_surfel_layer = 2.5;
  const std::vector<LossSpec> on = PaperLossTable(o);
  EXPECT_EQ(on.size(), off.size() + 2);
  for (Stage s : {Stage::kWarmup, Stage::kMutual}) {
    const LossSpec* r = Find(on, Branch::kSurfels2D, s, "surfel_layer");
    ASSERT_NE(r, nullptr);
    EXPECT_EQ(r->term, "surfel_layer");
    EXPECT_EQ(r->weight, 2.5);
  }
  EXPECT_TRUE(CheckLossTable(on).ok());
  EXPECT_TRUE(o.Validate().ok());
  o.lambda_surfel_layer = -1;
  EXPECT_FALSE(o.Validate().ok());
  // A JSON row turns it on with its own config, as any row.
  std::vector<LossSpec> t = off;
  ASSERT_TRUE(ApplyLossConfig(nlohmann::json::parse(R"({"losses": [{"branch": "2d", "stage":
      "mutual", "name": "layer", "term": "surfel_layer", "config": {"tau": 0.3}, "weight": 1}]})"),
                              "c.json", &t)
                  .ok());
  EXPECT_EQ(t.size(), off.size() + 1);
}

TEST(LossTableTest, BadConfigsAreRefusedWithTheRowAndTheProblem) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {R"({"losses": [{"branch": "2d", "stage": "warmup", "name": "x", "term": "nope",
          "weight": 1}]})",
       "c.json: loss row 2d/warmup/x: unknown loss term 'nope'"},
      {R"({"losses": [{"branch": "4d", "stage": "warmup", "name": "x"}]})",
       "c.json: losses[0]: \"branch\" must be"},
      {R"({"losses": [{"branch": "2d", "stage": "late", "name": "x"}]})", "\"stage\" must be"},
      {R"({"losses": [{"branch": "2d", "stage": "warmup", "name": "photo", "weight": -1}]})",
       "loss row 2d/warmup/photo: the weight must be finite and >= 0"},
      {R"({"losses": [{"branch": "2d", "stage": "warmup", "name": "new", "weight": 1}]})",
       "a new row needs \"term\" and \"weight\""},
      {R"({"losses": [{"branch": "2d", "stage": "warmup", "name": "photo", "wieght": 1}]})",
       "unknown key \"wieght\""},
      {R"({"losses": [{"branch": "2d", "stage": "warmup", "name": "t", "term": "tv",
          "config": {"buffer": "colour"}, "weight": 1}]})",
       "unknown buffer 'colour'"},
      {R"({"loses": []})", "c.json: expected an object with a \"losses\" array"},
      {R"({"losses": [{"branch": "2d", "stage": "both", "name": "layer", "term": "surfel_layer",
          "config": {"neighbours": 40}, "weight": 1}]})",
       "c.json: loss row 2d/warmup/layer: prior \"surfel_layer\": \"neighbours\" must be"},
  };
  for (const auto& [text, expected] : cases) {
    std::vector<LossSpec> t = PaperLossTable(SolverOptions());
    const std::vector<LossSpec> before = t;
    const Status s = ApplyLossConfig(nlohmann::json::parse(text), "c.json", &t);
    ASSERT_FALSE(s.ok()) << text;
    EXPECT_NE(s.message().find(expected), std::string::npos) << s.message();
    EXPECT_EQ(LossTableToJson(t), LossTableToJson(before)) << "a failed config changes nothing";
  }
  // Files: unreadable and not JSON, each named.
  std::vector<LossSpec> t;
  const std::string dir = testing::ScratchDir();
  Status s = ApplyLossConfigFile(dir + "/missing.json", &t);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("missing.json"), std::string::npos) << s.message();
  std::ofstream(dir + "/bad.json") << "{\"losses\": [";
  s = ApplyLossConfigFile(dir + "/bad.json", &t);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("bad.json: not valid JSON"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace mgsr
