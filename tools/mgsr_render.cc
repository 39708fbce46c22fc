// mgsr_render: renders a finished mgsr_solve output folder from new cameras.
//   mgsr_render --run OUT --output FRAMES --orbit 60      an orbit around the object
//   mgsr_render --run OUT --output FRAMES --views test    the scene's test (or train, all) views
// Per camera: composite, transmitted and reflected colour (3DGS branch), depth (colour-mapped) and
// normals (2DGS branch, or the 3DGS depth for a 3DGS-only run); an orbit also becomes orbit.mp4
// when ffmpeg is on the PATH. The run's metrics.json gives the scene, the backgrounds and the
// 2DGS rasteriser's settings; the models are its point_cloud_{2d,3d}.ply.
#include <gflags/gflags.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "mgsr/core/subprocess.h"
#include "mgsr/core/timer.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/model_ply.h"
#include "mgsr/io/scene.h"
#include "mgsr/loss/normal_consistency_loss.h"
#include "mgsr/mesh/tsdf_fusion.h"
#include "mgsr/model/environment_map.h"
#include "mgsr/render/gaussian_renderer.h"
#include "mgsr/render/surfel_renderer.h"
#include "mgsr/render/visualize.h"
#include "tools/openmp_wait.h"
#include "tools/tool_flags.h"

DEFINE_string(run, "", "An mgsr_solve output folder (metrics.json, point_cloud_*.ply).");
DEFINE_string(output, "", "Folder for the frames (created; existing frames are replaced).");
DEFINE_string(workspace, "",
              "The scene whose cameras to use (default: the run's scene from metrics.json).");
DEFINE_int32(orbit, 0, "Render N cameras on a circle around the object (0: --views instead).");
DEFINE_string(views, "test", "Without --orbit: the scene's test, train or all views.");
DEFINE_double(elevation, -1000,
              "Orbit elevation in degrees above the object's equator (default: the training "
              "cameras' mean).");
DEFINE_double(distance_scale, 1.0, "Orbit radius as a multiple of the cameras' median distance.");
DEFINE_int32(width, 0,
             "Orbit image width (0: the first training view's; height keeps its aspect).");
DEFINE_int32(fps, 30, "Frame rate of orbit.mp4.");
DEFINE_int32(sheet, 0,
             "Also write sheet.png: N evenly spaced cameras side by side, composite above depth "
             "above normals (0: none).");

namespace {

int Fail(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

struct Frame {
  std::string name;
  mgsr::Camera camera;
};

// The world's up as the training cameras see it (their -y axis, COLMAP's y points down).
Eigen::Vector3d MeanUp(const std::vector<mgsr::Camera>& cameras) {
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (const auto& c : cameras) up -= c.R.row(1).transpose();
  return up.norm() > 1e-9 ? up.normalized() : Eigen::Vector3d(0, 0, 1);
}

std::vector<Frame> OrbitFrames(const std::vector<mgsr::Camera>& train, int n) {
  const Eigen::Vector3d center = mgsr::LookAtCenter(train);
  const Eigen::Vector3d up = MeanUp(train);
  std::vector<double> distances;
  double elevation = 0;
  for (const auto& c : train) {
    const Eigen::Vector3d d = c.Center() - center;
    distances.push_back(d.norm());
    elevation += std::asin(std::clamp(d.normalized().dot(up), -1.0, 1.0));
  }
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  const double radius = distances[distances.size() / 2] * FLAGS_distance_scale;
  elevation = FLAGS_elevation > -999 ? FLAGS_elevation * M_PI / 180 : elevation / train.size();
  // Azimuth 0 is the first training camera's side.
  Eigen::Vector3d e1 = train[0].Center() - center;
  e1 -= e1.dot(up) * up;
  if (e1.norm() < 1e-9) e1 = up.unitOrthogonal();
  e1.normalize();
  const Eigen::Vector3d e2 = up.cross(e1);
  const mgsr::Camera& first = train[0];
  const int width = FLAGS_width > 0 ? FLAGS_width : first.width;
  const double s = static_cast<double>(width) / first.width;
  const int height = std::max(1, static_cast<int>(std::lround(first.height * s)));
  std::vector<Frame> frames;
  for (int i = 0; i < n; ++i) {
    const double az = 2 * M_PI * i / n;
    const Eigen::Vector3d pos =
        center + radius * (std::cos(elevation) * (std::cos(az) * e1 + std::sin(az) * e2) +
                           std::sin(elevation) * up);
    char name[32];
    std::snprintf(name, sizeof(name), "%04d", i);
    frames.push_back(
        {name, mgsr::LookAtCamera(pos, center, up, width, height, first.fx * s, first.fy * s)});
  }
  return frames;
}

// Tiles (each 3 channels, one size) into a grid of `columns`, 2 px white gutters.
mgsr::Image Sheet(const std::vector<mgsr::Image>& tiles, int columns) {
  const int w = tiles[0].width(), h = tiles[0].height(), g = 2;
  const int rows = (static_cast<int>(tiles.size()) + columns - 1) / columns;
  mgsr::Image out(columns * w + (columns - 1) * g, rows * h + (rows - 1) * g, 3);
  out.Fill(1.0f);
  for (size_t i = 0; i < tiles.size(); ++i) {
    const int ox = static_cast<int>(i % columns) * (w + g),
              oy = static_cast<int>(i / columns) * (h + g);
    for (int c = 0; c < 3; ++c)
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) out.at(c, oy + y, ox + x) = tiles[i].at(c, y, x);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  mgsr_tools::PreferShortOpenMpSpins(argv);
  mgsr_tools::ParseToolFlags(
      "mgsr_render --run OUTPUT_DIR --output FRAMES_DIR (--orbit N | --views test|train|all)",
      {{"Input and output", {"run", "output", "workspace"}},
       {"Cameras", {"orbit", "views", "elevation", "distance_scale", "width", "fps", "sheet"}}},
      &argc, &argv);
  if (FLAGS_run.empty() || FLAGS_output.empty()) return Fail("--run and --output are required");
  // As mgsr_synth: a frame is a few hundred bytes a pixel of buffers.
  if (FLAGS_width < 0 || FLAGS_width > 8192)
    return Fail("--width must be in [1, 8192] (0: the training width)");
  if (FLAGS_orbit < 0) return Fail("--orbit must be >= 0");
  if (FLAGS_orbit == 0 && FLAGS_views != "test" && FLAGS_views != "train" && FLAGS_views != "all")
    return Fail("--views must be test, train or all");
  if (!(FLAGS_distance_scale > 0)) return Fail("--distance_scale must be > 0");
  if (FLAGS_fps < 1) return Fail("--fps must be >= 1");
  if (FLAGS_sheet < 0) return Fail("--sheet must be >= 0");

  // The run: its settings and models.
  const std::string metrics_path = mgsr::JoinPath(FLAGS_run, "metrics.json");
  std::string text;
  if (mgsr::Status s = mgsr::ReadFileToString(metrics_path, &text); !s.ok())
    return Fail(s.message() + " (is --run a finished mgsr_solve output folder?)");
  const nlohmann::json m = nlohmann::json::parse(text, nullptr, false);
  if (m.is_discarded() || !m.is_object()) return Fail(metrics_path + ": not valid JSON");
  const std::string workspace =
      !FLAGS_workspace.empty() ? FLAGS_workspace : m.value("scene", std::string());
  if (workspace.empty()) return Fail(metrics_path + ": names no scene; give --workspace");
  const float bg2 = m.contains("background") ? m["background"].value("2d", 1.0f) : 1.0f;
  const float bg3 = m.contains("background") ? m["background"].value("3d", 0.0f) : 0.0f;
  const bool reflection = m.value("method", std::string("mgsr")) != "3dgs";
  mgsr::GaussianModel gaussians;
  mgsr::SurfelModel surfels;
  const std::string p3 = mgsr::JoinPath(FLAGS_run, "point_cloud_3d.ply");
  const std::string p2 = mgsr::JoinPath(FLAGS_run, "point_cloud_2d.ply");
  const bool has3 = mgsr::FileExists(p3), has2 = mgsr::FileExists(p2);
  if (!has3 && !has2) return Fail(FLAGS_run + ": holds neither point_cloud_3d.ply nor _2d.ply");
  if (has3) {
    if (mgsr::Status s = mgsr::ReadGaussianPly(p3, &gaussians); !s.ok()) return Fail(s.message());
  }
  if (has2) {
    if (mgsr::Status s = mgsr::ReadSurfelPly(p2, &surfels); !s.ok()) return Fail(s.message());
  }

  // Learnt backgrounds of a scene-level run (--background env): drawn behind every frame.
  mgsr::EnvironmentMap environment[2];  // 2DGS, 3DGS
  for (int b = 0; b < 2; ++b) {
    const std::string path =
        mgsr::JoinPath(FLAGS_run, mgsr::EnvironmentFileName(b == 0 ? "2d" : "3d"));
    if (!mgsr::FileExists(path)) continue;
    mgsr::Image image;
    if (mgsr::Status s = mgsr::ReadPfm(path, &image); !s.ok()) return Fail(s.message());
    if (!environment[b].FromImage(image)) return Fail(path + ": not a 3-channel environment map");
  }
  mgsr::EnvironmentRenderer environment_renderer;
  mgsr::Image environment_image;

  // The cameras.
  mgsr::Scene scene;
  if (mgsr::Status s = mgsr::LoadScene(workspace, mgsr::SceneOptions(), &scene); !s.ok())
    return Fail(s.message());
  std::vector<mgsr::Camera> train;
  for (int i : scene.TrainIndices()) train.push_back(scene.views[i].camera);
  if (train.empty()) return Fail(workspace + ": no training views to place the cameras by");
  std::vector<Frame> frames;
  if (FLAGS_orbit > 0) {
    frames = OrbitFrames(train, FLAGS_orbit);
  } else {
    for (size_t i = 0; i < scene.views.size(); ++i) {
      const auto& v = scene.views[i];
      if ((FLAGS_views == "test" && !v.is_test) || (FLAGS_views == "train" && v.is_test)) continue;
      frames.push_back({mgsr::FileStem(v.name), v.camera});
    }
    if (frames.empty()) return Fail(workspace + ": no " + FLAGS_views + " views");
  }
  if (mgsr::Status s = mgsr::MakeDirectories(FLAGS_output); !s.ok()) return Fail(s.message());

  mgsr::GaussianRenderer gaussian_renderer;
  mgsr::SurfelRenderer surfel_renderer;
  mgsr::DepthRange range;  // an orbit keeps the first frame's range, so colours do not flicker
  // Frames on the contact sheet: evenly spaced, as many as asked and there are.
  const int sheet_n = std::min<int>(FLAGS_sheet, static_cast<int>(frames.size()));
  std::vector<mgsr::Image> sheet_rows[3];
  auto on_sheet = [&](size_t i) {
    if (sheet_n == 0) return false;
    for (int k = 0; k < sheet_n; ++k)
      if (static_cast<size_t>(k) * frames.size() / sheet_n == i) return true;
    return false;
  };
  mgsr::Timer timer;
  for (size_t fi = 0; fi < frames.size(); ++fi) {
    const Frame& f = frames[fi];
    mgsr::Image composite;
    auto write = [&](const std::string& what, const mgsr::Image& image) {
      return mgsr::WriteImage(mgsr::JoinPath(FLAGS_output, f.name + "_" + what + ".png"), image);
    };
    mgsr::Status s = mgsr::Status::Ok();
    mgsr::Image depth, alpha, normal;
    if (has3) {
      mgsr::GaussianRenderOptions o;
      o.camera = f.camera;
      o.sh_degree = gaussians.max_sh_degree;
      o.reflection = reflection;
      std::fill(o.background, o.background + 3, bg3);
      if (!environment[1].texels.empty()) {
        environment_renderer.Render(environment[1], f.camera, &environment_image);
        o.background_image = &environment_image;
      }
      mgsr::GaussianRender g;
      gaussian_renderer.Forward(gaussians, o, &g);
      s = write("composite", g.color);
      composite = g.color;
      if (s.ok()) s = write("transmitted", g.tran);
      if (s.ok() && reflection) s = write("reflected", g.ref);
      if (!has2) {
        normal = mgsr::DepthToNormal(g.depth, f.camera);
        depth = std::move(g.depth);
        alpha = std::move(g.alpha);
      }
    }
    if (has2 && s.ok()) {
      mgsr::SurfelRenderOptions o;
      o.camera = f.camera;
      o.sh_degree = surfels.max_sh_degree;
      std::fill(o.background, o.background + 3, bg2);
      mgsr::Image environment_2d;
      if (!environment[0].texels.empty()) {
        environment_renderer.Render(environment[0], f.camera, &environment_2d);
        o.background_image = &environment_2d;
      }
      o.low_pass = m.value("surfel_low_pass", std::string("area")) == "reference"
                       ? mgsr::SurfelLowPass::kReference
                       : mgsr::SurfelLowPass::kAreaPreserving;
      o.filter_sigma = m.value("surfel_filter_sigma", o.filter_sigma);
      mgsr::SurfelRender r;
      surfel_renderer.Forward(surfels, o, &r);
      if (!has3) {
        s = write("composite", r.color);
        composite = r.color;
      }
      depth = std::move(r.depth);
      alpha = std::move(r.alpha);
      normal = std::move(r.normal_world);
    }
    if (s.ok()) {
      if (FLAGS_orbit == 0 || !(range.far > range.near))
        range = mgsr::RenderedDepthRange(depth, alpha);
      const mgsr::Image depth_rgb = mgsr::DepthColormap(depth, alpha, range);
      const mgsr::Image normal_rgb = mgsr::NormalColormap(normal, alpha);
      s = write("depth", depth_rgb);
      if (s.ok()) s = write("normal", normal_rgb);
      if (on_sheet(fi) && composite.SameShape(depth_rgb)) {
        sheet_rows[0].push_back(composite);
        sheet_rows[1].push_back(depth_rgb);
        sheet_rows[2].push_back(normal_rgb);
      }
    }
    if (!s.ok()) return Fail(s.message());
  }
  if (sheet_n > 0 && !sheet_rows[0].empty()) {
    std::vector<mgsr::Image> tiles;
    for (const auto& row : sheet_rows) tiles.insert(tiles.end(), row.begin(), row.end());
    const std::string path = mgsr::JoinPath(FLAGS_output, "sheet.png");
    if (mgsr::Status s =
            mgsr::WriteImage(path, Sheet(tiles, static_cast<int>(sheet_rows[0].size())));
        !s.ok())
      return Fail(s.message());
    std::printf("contact sheet: %s\n", path.c_str());
  }
  const double seconds = timer.ElapsedSeconds();
  std::printf("%zu cameras rendered into %s in %.1f s (%.0f ms each)\n", frames.size(),
              FLAGS_output.c_str(), seconds, 1000 * seconds / frames.size());
  if (FLAGS_orbit > 0) {
    const std::string ffmpeg = mgsr::FindProgram("ffmpeg");
    if (ffmpeg.empty()) {
      std::printf("ffmpeg is not on the PATH: frames only, no orbit.mp4\n");
      return 0;
    }
    const std::string video = mgsr::JoinPath(FLAGS_output, "orbit.mp4");
    const std::string partial = mgsr::JoinPath(FLAGS_output, "orbit.partial.mp4");
    // Written under another name and renamed, so a failed or interrupted encode leaves no
    // orbit.mp4 that looks finished.
    const mgsr::ProgramResult r = mgsr::RunProgram(
        {ffmpeg, "-y", "-loglevel", "error", "-framerate", std::to_string(FLAGS_fps), "-i",
         mgsr::JoinPath(FLAGS_output, "%04d_composite.png"), "-pix_fmt", "yuv420p", "-vf",
         "pad=ceil(iw/2)*2:ceil(ih/2)*2", partial},
        {}, mgsr::JoinPath(FLAGS_output, "ffmpeg.log"));
    std::error_code ec;
    if (!r.started || r.exit_code != 0) {
      std::filesystem::remove(partial, ec);
      return Fail("ffmpeg failed to write " + video + " (see ffmpeg.log there)");
    }
    std::filesystem::rename(partial, video, ec);
    if (ec) return Fail(video + ": cannot move the encoded video into place: " + ec.message());
    std::printf("video: %s\n", video.c_str());
  }
  return 0;
}
