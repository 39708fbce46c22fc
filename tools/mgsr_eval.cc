// mgsr_eval: scores a mesh against ground truth (NC, CD, F-score) or a folder of renders against
// ground-truth images (PSNR, SSIM), prints a table and optionally writes JSON.
//   mgsr_eval --mesh pred.ply --gt gt.ply [--json out.json]
//   mgsr_eval --renders DIR --gt_images DIR [--background black|white] [--json out.json]
//   mgsr_eval --run OUTPUT_DIR [--gt gt.ply]   an mgsr_solve output folder: the paper's table row
//                                                (NC x100, CD x1000, PSNR, SSIM, time)
#include <gflags/gflags.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "mgsr/core/timer.h"
#include "mgsr/eval/exposure_alignment.h"
#include "mgsr/eval/ground_truth.h"
#include "mgsr/eval/image_metrics.h"
#include "mgsr/eval/mesh_metrics.h"
#include "mgsr/eval/metrics_json.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/mesh_obj.h"
#include "mgsr/io/output_folder.h"
#include "mgsr/io/ply.h"
#include "tools/openmp_wait.h"
#include "tools/tool_flags.h"

DEFINE_string(mesh, "", "Predicted mesh (PLY, OBJ, or binary glTF .glb).");
DEFINE_string(gt, "", "Ground-truth mesh or point cloud (PLY, OBJ, or binary glTF .glb).");
DEFINE_int32(samples, 10000, "Points sampled on each surface.");
DEFINE_double(fscore_threshold, 0.01, "Distance threshold of the F-score, in scene units.");
DEFINE_uint64(seed, 0, "Sampling seed.");
DEFINE_double(pixel_footprint, 0,
              "Scene units one training pixel covers at the object: adds F-scores at 0.5, 1 and 2 "
              "footprints and the offset in pixels (--run: from metrics.json).");
DEFINE_string(gt_visible, "",
              "Optional ground-truth points to measure completeness from (e.g. "
              "gt_points_visible.ply).");
DEFINE_string(renders, "", "Folder of rendered images.");
DEFINE_string(gt_images, "", "Folder of ground-truth images with the same file names.");
DEFINE_string(background, "black",
              "Background that RGBA images are composited onto: black | white.");
DEFINE_string(json, "", "Write the results to this JSON file.");
DEFINE_string(run, "",
              "An mgsr_solve output folder (mesh.ply, metrics.json); --gt defaults to the scene's "
              "gt/mesh.ply.");

namespace {

int Fail(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

// RGB, with alpha composited onto the background.
mgsr::Image ToRgb(const mgsr::Image& im, float background) {
  if (im.channels() == 3) return im;
  mgsr::Image out(im.width(), im.height(), 3);
  for (int c = 0; c < 3; ++c) {
    const float* src = im.plane(im.channels() == 1 ? 0 : c);
    for (size_t i = 0; i < im.plane_size(); ++i) {
      const float a = im.channels() == 4 ? im.plane(3)[i] : 1.0f;
      out.plane(c)[i] = src[i] * a + background * (1 - a);
    }
  }
  return out;
}

void PrintMeshHeader() {
  std::printf("%-22s %8s %9s %9s %9s %10s %10s %8s %8s\n", "mesh", "NC x100", "CD x1000",
              "acc x1000", "comp x1000", "offset", "offset px", "inside", "F-score");
}

void PrintMeshRow(const std::string& label, const mgsr::MeshMetrics& m) {
  const double px = m.pixel_footprint > 0 ? m.signed_offset_median / m.pixel_footprint : NAN;
  std::printf("%-22s %8.2f %9.3f %9.3f %10.3f %+10.5f %+10.2f %7.1f%% %8.4f%s\n", label.c_str(),
              100 * m.normal_consistency, 1000 * m.chamfer, 1000 * m.accuracy,
              1000 * m.completeness, m.signed_offset_median, px, 100 * m.fraction_inside, m.fscore,
              m.ok ? "" : ("  (" + m.failure + ")").c_str());
}

mgsr::MeshMetricsOptions MeshOptionsFromFlags() {
  mgsr::MeshMetricsOptions o;
  o.num_samples = FLAGS_samples;
  o.seed = FLAGS_seed;
  o.fscore_threshold = FLAGS_fscore_threshold;
  o.pixel_footprint = FLAGS_pixel_footprint;
  return o;
}

int EvaluateMeshes(nlohmann::json* report) {
  mgsr::TriangleMesh pred, gt, visible;
  mgsr::Status s = mgsr::ReadMeshFile(FLAGS_mesh, &pred);
  if (!s.ok()) return Fail(s.message());
  s = mgsr::ReadMeshFile(FLAGS_gt, &gt);
  if (!s.ok()) return Fail(s.message());
  mgsr::MeshMetricsOptions o = MeshOptionsFromFlags();
  if (!FLAGS_gt_visible.empty()) {
    s = mgsr::ReadTriangleMesh(FLAGS_gt_visible, &visible);
    if (!s.ok()) return Fail(s.message());
    o.completeness_points = &visible;
  }
  const mgsr::MeshMetrics m = mgsr::EvaluateMesh(pred, gt, o);
  PrintMeshHeader();
  PrintMeshRow(mgsr::FileStem(FLAGS_mesh), m);
  nlohmann::json j = mgsr::MeshMetricsToJson(m);
  j["predicted"] = FLAGS_mesh;
  j["ground_truth"] = FLAGS_gt;
  j["samples"] = FLAGS_samples;
  j["fscore_threshold"] = FLAGS_fscore_threshold;
  (*report)["mesh"] = j;
  return 0;
}

int EvaluateImages(nlohmann::json* report) {
  if (!mgsr::DirectoryExists(FLAGS_renders))
    return Fail(FLAGS_renders + ": renders folder does not exist");
  if (!mgsr::DirectoryExists(FLAGS_gt_images))
    return Fail(FLAGS_gt_images + ": ground-truth folder does not exist");
  if (FLAGS_background != "black" && FLAGS_background != "white")
    return Fail("--background must be black or white");
  const float bg = FLAGS_background == "white" ? 1.0f : 0.0f;
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(FLAGS_renders)) {
    const std::string ext = e.path().extension().string();
    if (e.is_regular_file() && (ext == ".png" || ext == ".jpg"))
      names.push_back(e.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  if (names.empty()) return Fail(FLAGS_renders + ": no .png or .jpg images");
  nlohmann::json per_image = nlohmann::json::array();
  double psnr_sum = 0, ssim_sum = 0, apsnr_sum = 0, assim_sum = 0;
  std::printf("%-24s %8s %8s %10s %10s\n", "image", "PSNR", "SSIM", "PSNR (al.)", "SSIM (al.)");
  for (const std::string& name : names) {
    mgsr::Image render, gt;
    const std::string rp = mgsr::JoinPath(FLAGS_renders, name),
                      gp = mgsr::JoinPath(FLAGS_gt_images, name);
    mgsr::Status s = mgsr::ReadImage(rp, &render);
    if (!s.ok()) return Fail(s.message());
    s = mgsr::ReadImage(gp, &gt);
    if (!s.ok()) return Fail(s.message());
    if (render.width() != gt.width() || render.height() != gt.height()) {
      return Fail(rp + ": render is " + std::to_string(render.width()) + "x" +
                  std::to_string(render.height()) + " but " + gp + " is " +
                  std::to_string(gt.width()) + "x" + std::to_string(gt.height()));
    }
    const mgsr::Image a = ToRgb(render, bg), b = ToRgb(gt, bg);
    const double psnr = mgsr::Psnr(a, b), ssim = mgsr::Ssim(a, b);
    // Identical images have infinite PSNR; cap at 100 dB so means and JSON stay finite.
    const double psnr_capped = std::min(psnr, 100.0);
    // Exposure-aligned scores: affine colour fit of the render to the ground truth, then score.
    const mgsr::AlignedScores al = mgsr::ExposureAlignedScores(a, b);
    const double apsnr = std::min(al.psnr, 100.0);
    psnr_sum += psnr_capped;
    ssim_sum += ssim;
    apsnr_sum += apsnr;
    assim_sum += al.ssim;
    std::printf("%-24s %8.3f %8.4f %10.3f %10.4f\n", name.c_str(), psnr_capped, ssim, apsnr,
                al.ssim);
    per_image.push_back({{"name", name},
                         {"psnr", psnr_capped},
                         {"ssim", ssim},
                         {"psnr_aligned", apsnr},
                         {"ssim_aligned", al.ssim}});
  }
  const double n = static_cast<double>(names.size());
  std::printf("%-24s %8.3f %8.4f %10.3f %10.4f\n", "mean", psnr_sum / n, ssim_sum / n,
              apsnr_sum / n, assim_sum / n);
  (*report)["images"] = {{"renders", FLAGS_renders},       {"ground_truth", FLAGS_gt_images},
                         {"background", FLAGS_background}, {"count", names.size()},
                         {"psnr", psnr_sum / n},           {"ssim", ssim_sum / n},
                         {"psnr_aligned", apsnr_sum / n},  {"ssim_aligned", assim_sum / n},
                         {"per_image", per_image}};
  return 0;
}

int EvaluateRun(nlohmann::json* report) {
  const std::string metrics_path = mgsr::JoinPath(FLAGS_run, "metrics.json");
  std::string text;
  mgsr::Status s = mgsr::ReadFileToString(metrics_path, &text);
  if (!s.ok()) return Fail(s.message() + " (is --run an mgsr_solve output folder?)");
  nlohmann::json run;
  try {
    run = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    return Fail(metrics_path + ": invalid JSON: " + e.what());
  }
  // The mesh must be the one this metrics.json describes, not another run's left beside it.
  s = mgsr::VerifyOutputManifest(FLAGS_run, run);
  if (!s.ok()) return Fail(s.message());
  if (!run["files"].contains("mesh.ply")) return Fail(metrics_path + ": the run wrote no mesh.ply");
  mgsr::GroundTruthGeometry gt;
  if (!FLAGS_gt.empty()) {
    s = mgsr::ReadMeshFile(FLAGS_gt, &gt.mesh);
    if (!s.ok()) return Fail(s.message());
    gt.mesh_path = FLAGS_gt;
  } else if (run.contains("scene") && run["scene"].is_string()) {
    s = mgsr::FindGroundTruth(run["scene"].get<std::string>(), &gt);
    if (!s.ok()) return Fail(s.message());
  }
  if (!gt.found()) return Fail(FLAGS_run + ": its scene has no ground-truth mesh (pass --gt)");
  mgsr::TriangleMesh pred;
  s = mgsr::ReadTriangleMesh(mgsr::JoinPath(FLAGS_run, "mesh.ply"), &pred);
  if (!s.ok()) return Fail(s.message());
  mgsr::MeshMetricsOptions o = MeshOptionsFromFlags();
  if (o.pixel_footprint <= 0 && run.contains("mesh"))
    o.pixel_footprint = run["mesh"].value("pixel_footprint", 0.0);
  if (!gt.visible_path.empty()) o.completeness_points = &gt.visible_points;
  const mgsr::MeshMetrics m = mgsr::EvaluateMesh(pred, gt.mesh, o);
  // The ceiling as the run measured it (same cameras and fusion), when it did.
  const bool has_ceiling = run.contains("mesh") && run["mesh"].contains("ceiling");
  const double psnr = run["test"].value("psnr", 0.0), ssim = run["test"].value("ssim", 0.0);
  const double psnr_al = run["test"].value("psnr_aligned", 0.0);
  const double seconds = run["seconds"].value("total", 0.0);
  std::printf("%-24s %8s %9s %8s %8s %11s %9s\n", "run", "NC x100", "CD x1000", "PSNR", "SSIM",
              "PSNR (al.)", "time (s)");
  std::printf("%-24s %8.2f %9.3f %8.2f %8.4f %11.2f %9.1f%s\n", mgsr::FileStem(FLAGS_run).c_str(),
              100 * m.normal_consistency, 1000 * m.chamfer, psnr, ssim, psnr_al, seconds,
              m.ok ? "" : ("  (" + m.failure + ")").c_str());
  std::printf("\n");
  PrintMeshHeader();
  PrintMeshRow("mesh", m);
  if (has_ceiling) {
    const nlohmann::json& c = run["mesh"]["ceiling"];
    std::printf("%-22s %8.2f %9.3f   (exact depth, same cameras and fusion, from metrics.json)\n",
                "ceiling", 100 * c.value("nc", 0.0), 1000 * c.value("cd", 0.0));
  }
  nlohmann::json mesh_json = mgsr::MeshMetricsToJson(m);
  (*report)["run"] = {
      {"folder", FLAGS_run},
      {"ground_truth", gt.mesh_path},
      {"nc", m.normal_consistency},
      {"cd", std::isfinite(m.chamfer) ? nlohmann::json(m.chamfer) : nlohmann::json()},
      {"fscore", m.fscore},
      {"mesh", mesh_json},
      {"psnr", psnr},
      {"ssim", ssim},
      {"psnr_aligned", psnr_al},
      {"seconds", seconds}};
  if (has_ceiling) (*report)["run"]["ceiling"] = run["mesh"]["ceiling"];
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  mgsr_tools::PreferShortOpenMpSpins(argv);
  mgsr_tools::ParseToolFlags(
      "mgsr_eval --mesh pred.ply --gt gt.ply | --renders DIR --gt_images DIR | --run DIR [--gt "
      "gt.ply]  [--json out.json]",
      {{"What to score", {"run", "mesh", "gt", "gt_visible", "renders", "gt_images"}},
       {"Mesh metrics", {"samples", "fscore_threshold", "pixel_footprint", "seed"}},
       {"Image metrics", {"background"}},
       {"Output", {"json"}}},
      &argc, &argv);
  const bool run_mode = !FLAGS_run.empty();
  const bool mesh_mode = !run_mode && (!FLAGS_mesh.empty() || !FLAGS_gt.empty());
  const bool image_mode = !FLAGS_renders.empty() || !FLAGS_gt_images.empty();
  if (!mesh_mode && !image_mode && !run_mode) {
    std::fprintf(stderr, "error: give --mesh and --gt, --renders and --gt_images, or --run\n");
    return 2;
  }
  if (mesh_mode && (FLAGS_mesh.empty() || FLAGS_gt.empty())) {
    std::fprintf(stderr, "error: --mesh and --gt go together\n");
    return 2;
  }
  if (image_mode && (FLAGS_renders.empty() || FLAGS_gt_images.empty())) {
    std::fprintf(stderr, "error: --renders and --gt_images go together\n");
    return 2;
  }
  if (FLAGS_samples < 1) return Fail("--samples must be >= 1");
  nlohmann::json report;
  mgsr::Timer timer;
  if (run_mode && EvaluateRun(&report) != 0) return 1;
  if (mesh_mode && EvaluateMeshes(&report) != 0) return 1;
  if (image_mode && EvaluateImages(&report) != 0) return 1;
  report["seconds"] = timer.ElapsedSeconds();
  if (!FLAGS_json.empty()) {
    const mgsr::Status s = mgsr::WriteStringToFileAtomic(FLAGS_json, report.dump(2) + "\n");
    if (!s.ok()) return Fail(s.message());
  }
  return 0;
}
