// mgsr_synth: writes a synthetic scene with exact ground truth (COLMAP workspace + Blender json +
// ground-truth mesh, depth and normal maps). See mgsr/synth/synthetic_scene.h.
#include <gflags/gflags.h>

#include <cstdio>

#include "mgsr/core/timer.h"
#include "mgsr/synth/synthetic_scene.h"
#include "tools/openmp_wait.h"
#include "tools/tool_flags.h"

DEFINE_string(output, "", "Folder to write the scene into (created).");
DEFINE_string(scene_type, "object",
              "object: the shape alone, cameras on a sphere around it; outdoor: on a textured "
              "ground under a sky, cameras at standing height on a wide orbit, no masks; indoor: "
              "the same in a closed room.");
DEFINE_double(region_half, 2.0,
              "Scene-level: half the side of the central region (gt/region.json) whose ground "
              "truth gt/mesh.ply holds.");
DEFINE_string(shape, "sphere",
              "sphere | torus | rounded_box | dented (concavities and a thin rod)");
DEFINE_int32(detail, 1, "Mesh detail 0..2.");
DEFINE_string(mesh, "",
              "A mesh file (OBJ, PLY or glb) to render instead of --shape; centred and scaled to "
              "radius 1.");
DEFINE_string(texture, "noise",
              "noise (low-contrast solid noise) or print (a high-contrast printed pattern).");
DEFINE_int32(num_views, 48, "Number of views (cameras on a sphere around the object).");
DEFINE_int32(width, 128, "Image width in pixels.");
DEFINE_int32(height, 128, "Image height in pixels.");
DEFINE_double(distance, 3.5, "Camera distance from the object centre (object radius is 1).");
DEFINE_int32(test_every, 8, "Every Nth view is a test view (0: none).");
DEFINE_uint64(seed, 1, "Seed for cameras, lights and points.");
DEFINE_int32(supersampling, 2, "Samples per pixel per axis.");
DEFINE_double(specular, 0.7, "Highlight strength.");
DEFINE_double(shininess, 80, "Highlight sharpness (Blinn-Phong exponent).");
DEFINE_double(mirror, 0.0, "0..1: mirror-like reflection of the environment.");
DEFINE_bool(varying_light, true,
            "Change light direction, intensity, colour and exposure per view.");
DEFINE_double(exposure_stops, 1.0, "Per-view exposure range +-stops (with --varying_light).");
DEFINE_int32(num_points, 2000, "Surface points written to points3D.");
DEFINE_bool(text, false, "Write sparse/0 in COLMAP's text format instead of binary.");
DEFINE_double(pose_noise_deg, 0,
              "Noisy poses: rms rotation error (degrees) of the written cameras.");
DEFINE_double(pose_noise_rel, 0,
              "Noisy poses: rms camera-centre error, as a fraction of the camera distance.");
DEFINE_bool(masks, true, "Write masks/ and RGBA photos; false: RGB photos on grey, no masks.");
DEFINE_bool(constant_light_copy, false, "Also render images_constant/ under one fixed light.");
DEFINE_string(lens, "pinhole",
              "The photos' lens: pinhole, opencv (barrel with tangential terms) or fisheye "
              "(OpenCV's equidistant model); a distorted scene carries its lens in sparse/ and in "
              "one nerfstudio transforms.json.");
DEFINE_bool(per_frame_focal, false,
            "Each view its own focal length (x0.85..1.15): per-frame intrinsics in "
            "transforms.json, one COLMAP camera per view.");

int main(int argc, char** argv) {
  mgsr_tools::PreferShortOpenMpSpins(argv);
  mgsr_tools::ParseToolFlags(
      "mgsr_synth --output DIR [--shape sphere] [--num_views 48] ...",
      {{"Output", {"output", "text", "masks", "constant_light_copy"}},
       {"Scene", {"scene_type", "region_half"}},
       {"Object",
        {"shape", "mesh", "detail", "texture", "specular", "shininess", "mirror", "num_points"}},
       {"Cameras and photos",
        {"num_views", "width", "height", "distance", "test_every", "supersampling",
         "pose_noise_deg", "pose_noise_rel", "lens", "per_frame_focal"}},
       {"Light", {"varying_light", "exposure_stops"}},
       {"Randomness", {"seed"}}},
      &argc, &argv);
  if (FLAGS_output.empty()) {
    std::fprintf(stderr, "error: --output is required\n");
    return 2;
  }
  mgsr::SynthOptions o;
  o.scene_type = FLAGS_scene_type;
  o.region_half = FLAGS_region_half;
  o.shape = FLAGS_shape;
  o.mesh_path = FLAGS_mesh;
  o.texture = FLAGS_texture;
  o.detail = FLAGS_detail;
  o.num_views = FLAGS_num_views;
  o.width = FLAGS_width;
  o.height = FLAGS_height;
  o.distance = FLAGS_distance;
  o.test_every = FLAGS_test_every;
  o.seed = FLAGS_seed;
  o.supersampling = FLAGS_supersampling;
  o.specular = FLAGS_specular;
  o.shininess = FLAGS_shininess;
  o.mirror = FLAGS_mirror;
  o.varying_light = FLAGS_varying_light;
  o.exposure_stops = FLAGS_exposure_stops;
  o.num_points = FLAGS_num_points;
  o.write_text_model = FLAGS_text;
  o.constant_light_copy = FLAGS_constant_light_copy;
  o.pose_noise_deg = FLAGS_pose_noise_deg;
  o.pose_noise_rel = FLAGS_pose_noise_rel;
  o.masks = FLAGS_masks;
  o.lens = FLAGS_lens;
  o.per_frame_focal = FLAGS_per_frame_focal;
  mgsr::Timer timer;
  const mgsr::Status s = mgsr::WriteSyntheticScene(o, FLAGS_output);
  if (!s.ok()) {
    std::fprintf(stderr, "error: %s\n", s.message().c_str());
    return 1;
  }
  const std::string what = o.mesh_path.empty() ? o.shape : o.mesh_path;
  std::printf("wrote %s %s scene (%d views, %dx%d) to %s in %.1f s\n", what.c_str(),
              o.scene_type.c_str(), o.num_views, o.width, o.height, FLAGS_output.c_str(),
              timer.ElapsedSeconds());
  return 0;
}
