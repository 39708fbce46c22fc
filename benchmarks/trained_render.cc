// mgsr_trained_render_bench: the two branches' renders, forward and backward, on a trained model
// over its scene's training views, as training renders them (reflection on, the surfels without
// their distortion and with the run's screen low-pass), in ms per view per stage. The synthetic
// BM_* scenes have no opaque surface; a trained model does, and behind it most tile rows of a
// tile's later entries have nothing left to blend, which is where several of the rasterizers'
// shortcuts pay. It also prints a digest of every output and gradient, so two builds can show they
// compute the same renders to the bit.
//
//   mgsr_trained_render_bench --run RUN_DIR --workspace SCENE [--rounds 3] [--threads 2]
//                             [--long_side N]
//
// RUN_DIR is a finished `mgsr_solve` output folder (point_cloud_3d.ply, point_cloud_2d.ply,
// metrics.json); SCENE its workspace.
#include <gflags/gflags.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mgsr/core/profiler.h"
#include "mgsr/core/sha256.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/render/gaussian_renderer.h"
#include "mgsr/render/surfel_renderer.h"

DEFINE_string(run, "", "A finished mgsr_solve output folder (its models and metrics.json).");
DEFINE_string(workspace, "", "The run's scene (COLMAP workspace or Blender folder).");
DEFINE_int32(rounds, 3, "Timed passes over the training views (after one untimed pass).");
DEFINE_int32(threads, 2, "OpenMP threads.");
DEFINE_int32(long_side, 0,
             "Render every view resized so that its long side is this many px, as training at "
             "that size (or a coarse start's level) renders it; 0: the cameras' own size.");

namespace {

int Fail(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

// Upstream gradients on the outputs the training losses read: small, fixed, sign-varying values.
void FillGradient(mgsr::Image* im) {
  for (size_t i = 0; i < im->size(); ++i)
    im->data()[i] = 1e-5f * static_cast<float>(static_cast<int>((i * 7919) % 13) - 6);
}

void Append(const std::vector<float>& v, std::string* bytes) {
  bytes->append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(float));
}
void Append(const mgsr::Image& im, std::string* bytes) {
  bytes->append(reinterpret_cast<const char*>(im.data()), im.size() * sizeof(float));
}

}  // namespace

int main(int argc, char** argv) {
  gflags::SetUsageMessage("mgsr_trained_render_bench --run RUN_DIR --workspace SCENE");
  gflags::ParseCommandLineFlags(&argc, &argv, true);
  if (FLAGS_run.empty() || FLAGS_workspace.empty()) return Fail("--run and --workspace are needed");
  if (FLAGS_rounds < 1 || FLAGS_threads < 1) return Fail("--rounds and --threads must be >= 1");
  omp_set_num_threads(FLAGS_threads);

  mgsr::GaussianModel gaussians;
  mgsr::SurfelModel surfels;
  for (const mgsr::Status& s :
       {mgsr::ReadGaussianPly(FLAGS_run + "/point_cloud_3d.ply", &gaussians),
        mgsr::ReadSurfelPly(FLAGS_run + "/point_cloud_2d.ply", &surfels)}) {
    if (!s.ok()) return Fail(s.message());
  }
  std::string text;
  const std::string metrics_path = FLAGS_run + "/metrics.json";
  if (!mgsr::ReadFileToString(metrics_path, &text).ok())
    return Fail(metrics_path + ": cannot be read");
  const nlohmann::json metrics = nlohmann::json::parse(text, nullptr, false);
  if (metrics.is_discarded() || !metrics.contains("surfel_filter_sigma") ||
      !metrics.contains("surfel_low_pass"))
    return Fail(metrics_path + ": not a run's metrics (no surfel_filter_sigma / surfel_low_pass)");
  mgsr::Scene scene;
  mgsr::SceneOptions scene_options;
  scene_options.load_images = false;
  if (const mgsr::Status s = mgsr::LoadScene(FLAGS_workspace, scene_options, &scene); !s.ok())
    return Fail(s.message());
  const std::vector<int> views = scene.TrainIndices();
  if (views.empty()) return Fail(FLAGS_workspace + ": no training views");
  if (FLAGS_long_side < 0) return Fail("--long_side must be >= 0");
  if (FLAGS_long_side > 0) {
    for (mgsr::View& v : scene.views) {
      mgsr::Camera& c = v.camera;
      const double scale = static_cast<double>(FLAGS_long_side) / std::max(c.width, c.height);
      c = c.Resized(std::max(1, static_cast<int>(std::lround(c.width * scale))),
                    std::max(1, static_cast<int>(std::lround(c.height * scale))));
    }
  }

  mgsr::GaussianRenderOptions gaussian_options;
  gaussian_options.sh_degree = 3;
  gaussian_options.reflection = true;
  mgsr::SurfelRenderOptions surfel_options;
  surfel_options.sh_degree = 3;
  surfel_options.distortion = false;
  surfel_options.filter_sigma = metrics["surfel_filter_sigma"].get<float>();
  surfel_options.low_pass = metrics["surfel_low_pass"] == "area"
                                ? mgsr::SurfelLowPass::kAreaPreserving
                                : mgsr::SurfelLowPass::kReference;

  mgsr::GaussianRenderer gaussian_renderer;
  mgsr::SurfelRenderer surfel_renderer;
  mgsr::GaussianRender gaussian_render;
  mgsr::SurfelRender surfel_render;
  mgsr::GaussianGradients gaussian_grads;
  mgsr::SurfelGradients surfel_grads;
  mgsr::GaussianRenderGrad gaussian_grad;
  mgsr::SurfelRenderGrad surfel_grad;
  std::string gaussian_bytes, surfel_bytes;  // every output and gradient of the first pass
  for (int round = 0; round <= FLAGS_rounds; ++round) {
    mgsr::Profiler::SetEnabled(round > 0);  // the first pass warms the buffers and is not timed
    for (int v : views) {
      const mgsr::Camera& camera = scene.views[v].camera;
      const int w = camera.width, h = camera.height;
      if (gaussian_grad.color.width() != w || gaussian_grad.color.height() != h) {
        for (mgsr::Image* im : {&gaussian_grad.color, &gaussian_grad.tran, &surfel_grad.color,
                                &surfel_grad.normal_world})
          *im = mgsr::Image(w, h, 3);
        for (mgsr::Image* im : {&gaussian_grad.depth, &surfel_grad.depth})
          *im = mgsr::Image(w, h, 1);
        for (mgsr::Image* im : {&gaussian_grad.color, &gaussian_grad.tran, &gaussian_grad.depth,
                                &surfel_grad.color, &surfel_grad.normal_world, &surfel_grad.depth})
          FillGradient(im);
      }
      gaussian_options.camera = camera;
      surfel_options.camera = camera;
      {
        mgsr::ProfileContext branch("3DGS");
        gaussian_renderer.Forward(gaussians, gaussian_options, &gaussian_render);
        gaussian_renderer.Backward(gaussians, gaussian_options, gaussian_render, gaussian_grad,
                                   &gaussian_grads);
      }
      {
        mgsr::ProfileContext branch("2DGS");
        surfel_renderer.Forward(surfels, surfel_options, &surfel_render);
        surfel_renderer.Backward(surfels, surfel_options, surfel_render, surfel_grad,
                                 &surfel_grads);
      }
      if (round == 0) {
        for (const mgsr::Image* im :
             {&gaussian_render.color, &gaussian_render.tran, &gaussian_render.ref,
              &gaussian_render.weight, &gaussian_render.depth, &gaussian_render.alpha})
          Append(*im, &gaussian_bytes);
        for (const mgsr::Image* im :
             {&surfel_render.color, &surfel_render.depth, &surfel_render.alpha,
              &surfel_render.normal_world, &surfel_render.median_depth})
          Append(*im, &surfel_bytes);
        const mgsr::GaussianModel& dg = gaussian_grads.params;
        for (const std::vector<float>* g :
             {&dg.means, &dg.log_scales, &dg.quats, &dg.opacity_logits, &dg.ref_opacity_logits,
              &dg.beta_logits, &dg.sh, &dg.ref_sh})
          Append(*g, &gaussian_bytes);
        const mgsr::SurfelModel& ds = surfel_grads.params;
        for (const std::vector<float>* g :
             {&ds.means, &ds.log_scales, &ds.quats, &ds.opacity_logits, &ds.sh})
          Append(*g, &surfel_bytes);
      }
    }
  }
  const double renders = static_cast<double>(FLAGS_rounds) * views.size();
  std::printf("%zu Gaussians, %zu surfels, %zu views x %d rounds, %d threads; ms per view:\n",
              gaussians.size(), surfels.size(), views.size(), FLAGS_rounds, FLAGS_threads);
  double total = 0;
  for (const mgsr::ProfileEntry& e : mgsr::Profiler::Take()) {
    std::printf("  %-5s %-28s %8.2f\n", e.context.c_str(), e.name.c_str(),
                1000 * e.seconds / renders);
    total += e.seconds;
  }
  std::printf("  %-34s %8.2f\n", "total", 1000 * total / renders);
  // Two builds that print the same digests rendered the same images and gradients to the bit.
  std::printf("digest of the outputs and gradients: 3DGS %s, 2DGS %s\n",
              mgsr::Sha256Hex(gaussian_bytes).substr(0, 16).c_str(),
              mgsr::Sha256Hex(surfel_bytes).substr(0, 16).c_str());
  return 0;
}
