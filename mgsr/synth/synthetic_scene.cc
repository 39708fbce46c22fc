#include "mgsr/synth/synthetic_scene.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "mgsr/core/rng.h"
#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"
#include "mgsr/io/mesh_obj.h"
#include "mgsr/io/ply.h"
#include "mgsr/synth/ray_caster.h"
#include "mgsr/synth/scene_layout.h"
#include "mgsr/synth/shapes.h"
#include "mgsr/synth/solid_noise.h"

namespace mgsr {
namespace {

constexpr double kPi = 3.14159265358979323846;

using synth::Smoothstep;
using synth::ValueNoise;

// Diffuse albedo (linear): two colours mixed by multi-scale noise, with fine dark speckles so
// feature matchers (SIFT) find texture.
Eigen::Vector3d Albedo(const Eigen::Vector3d& p) {
  const double n = 0.6 * ValueNoise(p * 4.0 + Eigen::Vector3d(3.1, 7.7, 1.3)) +
                   0.4 * ValueNoise(p * 11.0 + Eigen::Vector3d(5.2, 0.4, 9.9));
  const Eigen::Vector3d a(0.75, 0.32, 0.12), b(0.15, 0.45, 0.70);
  Eigen::Vector3d c = a + (b - a) * Smoothstep(0.35, 0.65, n);
  const double speck = ValueNoise(p * 28.0);
  c *= 0.45 + 0.55 * Smoothstep(0.25, 0.45, speck);
  return c;
}

// A printed pattern (linear albedo): dark ornaments and thin lines on cream, in two inks, with
// edges a pixel sharp at the usual scales: what a wallpaper or a poster shows.
Eigen::Vector3d PrintAlbedo(const Eigen::Vector3d& p) {
  const double u = std::sin(9.0 * p.x() + 2.1 * std::sin(7.0 * p.z())) *
                   std::sin(9.0 * p.z() + 2.1 * std::sin(7.0 * p.y())) *
                   std::cos(5.0 * p.y() - 1.3 * p.x());
  const double stripes = std::sin(31.0 * (p.x() + 0.7 * p.y() - 0.4 * p.z()));
  const double ink = Smoothstep(0.18, 0.24, u) + Smoothstep(0.93, 0.97, stripes);
  const Eigen::Vector3d paper(0.82, 0.78, 0.66), ink_a(0.09, 0.11, 0.28), ink_b(0.42, 0.06, 0.05);
  const double which = Smoothstep(0.45, 0.55, ValueNoise(p * 2.5 + Eigen::Vector3d(1.7, 4.2, 0.3)));
  const Eigen::Vector3d ink_color = ink_a + (ink_b - ink_a) * which;
  return paper + (ink_color - paper) * std::min(1.0, ink);
}

// A simple environment: blue sky brightening to the horizon, a dark checkered ground, and the key
// light's colour as a bright disk around its direction.
Eigen::Vector3d Environment(const Eigen::Vector3d& d, const ViewLight& light) {
  Eigen::Vector3d c;
  if (d.z() >= 0) {
    const double t = std::pow(d.z(), 0.5);
    c = Eigen::Vector3d(0.95, 0.92, 0.85) * (1 - t) + Eigen::Vector3d(0.25, 0.45, 0.9) * t;
  } else {
    const double s = 1.0 / std::max(1e-3, -d.z());
    const bool check = (static_cast<long>(std::floor(d.x() * s * 2)) +
                        static_cast<long>(std::floor(d.y() * s * 2))) &
                       1;
    c = check ? Eigen::Vector3d(0.12, 0.11, 0.10) : Eigen::Vector3d(0.30, 0.28, 0.26);
  }
  c *= light.environment;
  if (d.dot(light.direction) > 0.995) c += 6.0 * light.intensity * light.color;
  return c;
}

double LinearToSrgb(double x) {
  x = std::min(1.0, std::max(0.0, x));
  return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1.0 / 2.4) - 0.055;
}

// Ambient, Lambert with a shadow ray and (specular > 0) a Blinn-Phong highlight, in linear
// unexposed units; view_dir points from the eye to the surface, n may face either way.
Eigen::Vector3d DirectLight(const RayCaster& shadow_caster, const Eigen::Vector3d& albedo,
                            const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                            const Eigen::Vector3d& view_dir, const ViewLight& light,
                            double specular, double shininess) {
  const Eigen::Vector3d sky(0.55, 0.65, 0.85), ground(0.25, 0.23, 0.2);
  const Eigen::Vector3d ambient =
      0.35 * light.environment * (ground + (sky - ground) * (0.5 + 0.5 * n.z()));
  const double ndotl = n.dot(light.direction);
  double visible = 0;
  if (ndotl > 0)
    visible = shadow_caster.Occluded(p + 1e-6 * n, light.direction, 1e-6, 1e3) ? 0.0 : 1.0;
  Eigen::Vector3d c =
      albedo.cwiseProduct(ambient + light.intensity * std::max(0.0, ndotl) * visible * light.color);
  if (visible > 0 && specular > 0) {
    const Eigen::Vector3d h = (light.direction - view_dir).normalized();
    const double spec = std::pow(std::max(0.0, n.dot(h)), shininess);
    // Normalised so the peak is bright enough to clip: a highlight that moves with the light.
    c += specular * light.intensity * spec * (shininess + 8) / 8.0 * light.color * 0.25;
  }
  return c;
}

// The object's colour: direct light, then mixed with what its mirror reflects (`reflect` of the
// reflected direction), Fresnel-weighted; exposure applied by the caller.
template <typename Reflect>
Eigen::Vector3d ShadeObject(const RayCaster& shadow_caster, const Eigen::Vector3d& p,
                            const Eigen::Vector3d& n_in, const Eigen::Vector3d& view_dir,
                            const ViewLight& light, const SynthOptions& o, Reflect reflect) {
  Eigen::Vector3d n = n_in;
  if (n.dot(view_dir) > 0) n = -n;  // inside faces of open parts
  const Eigen::Vector3d albedo = o.texture == "print" ? PrintAlbedo(p) : Albedo(p);
  Eigen::Vector3d c =
      DirectLight(shadow_caster, albedo, p, n, view_dir, light, o.specular, o.shininess);
  if (o.mirror > 0) {
    const Eigen::Vector3d r = view_dir - 2 * view_dir.dot(n) * n;
    const double cos_theta = std::max(0.0, -view_dir.dot(n));
    const double fresnel = 0.04 + 0.96 * std::pow(1 - cos_theta, 5.0);
    const double w = o.mirror * (0.6 + 0.4 * fresnel);
    c = (1 - w) * c + w * reflect(p + 1e-6 * n, r);
  }
  return c;
}

// The diffuse albedo (linear) of a surface point by what it is made of.
Eigen::Vector3d MaterialAlbedo(SurfaceMaterial material, const Eigen::Vector3d& p, SceneType type) {
  switch (material) {
    case SurfaceMaterial::kObject:
      return Albedo(p);
    case SurfaceMaterial::kGround:
      return GroundAlbedo(p, type);
    case SurfaceMaterial::kWall:
      break;
  }
  return WallAlbedo(p);
}

ViewLight FixedLight() {
  ViewLight l;
  l.direction = Eigen::Vector3d(0.5, -0.4, 0.8).normalized();
  l.intensity = 1.1;
  return l;
}

}  // namespace

Status SynthOptions::Validate() const {
  SceneType type;
  if (!ParseSceneType(scene_type, &type))
    return Status::Error("unknown --scene_type '" + scene_type + "' (object, outdoor or indoor)");
  if (type != SceneType::kObject) {
    if (!(region_half >= 1.0 && region_half <= 4.0))
      return Status::Error("--region_half must be in [1, 4] (the object has radius 1)");
    if (!(distance > region_half * 0.75))
      return Status::Error("--distance must be > 0.75 x --region_half for a scene-level capture");
    if (type == SceneType::kIndoor && !(distance <= 4.5))
      return Status::Error("--distance must be <= 4.5 indoors (the room is 10 units wide)");
  }
  if (texture != "noise" && texture != "print")
    return Status::Error("unknown --texture '" + texture + "' (noise or print)");
  TriangleMesh unused;
  if (mesh_path.empty() && !MakeShape(shape, 0, &unused)) {
    std::string names;
    for (const auto& n : ShapeNames()) names += (names.empty() ? "" : ", ") + n;
    return Status::Error("unknown shape '" + shape + "' (choose one of: " + names + ")");
  }
  if (num_views < 3) return Status::Error("--num_views must be >= 3");
  if (width < 8 || height < 8 || width > 8192 || height > 8192)
    return Status::Error("--width/--height must be in [8, 8192]");
  if (!(fov_x > 0.05 && fov_x < 3.0)) return Status::Error("--fov_x must be in (0.05, 3) radians");
  if (!(distance > 1.2)) return Status::Error("--distance must be > 1.2 (the object has radius 1)");
  if (supersampling < 1 || supersampling > 8)
    return Status::Error("--supersampling must be in [1, 8]");
  if (test_every < 0) return Status::Error("--test_every must be >= 0");
  if (lens != "pinhole" && lens != "opencv" && lens != "fisheye")
    return Status::Error("unknown --lens '" + lens + "' (pinhole, opencv or fisheye)");
  if (!(mirror >= 0 && mirror <= 1)) return Status::Error("--mirror must be in [0, 1]");
  if (!(exposure_stops >= 0 && exposure_stops <= 6))
    return Status::Error("--exposure_stops must be in [0, 6]");
  if (!(pose_noise_deg >= 0 && pose_noise_deg <= 30))
    return Status::Error("--pose_noise_deg must be in [0, 30]");
  if (!(pose_noise_rel >= 0 && pose_noise_rel <= 0.5))
    return Status::Error("--pose_noise_rel must be in [0, 0.5]");
  return Status::Ok();
}

void NormaliseMesh(TriangleMesh* mesh, double radius) {
  if (mesh->vertices.empty()) return;
  Eigen::Vector3d lo = mesh->vertices[0], hi = lo;
  for (const auto& p : mesh->vertices) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  double far = 0;
  for (const auto& p : mesh->vertices) far = std::max(far, (p - centre).norm());
  const double s = far > 0 ? radius / far : 1.0;
  for (auto& p : mesh->vertices) p = (p - centre) * s;
}

Status MakeObjectMesh(const SynthOptions& o, TriangleMesh* mesh) {
  if (o.mesh_path.empty()) {
    if (!MakeShape(o.shape, o.detail, mesh))
      return Status::Error("unknown shape '" + o.shape + "'");
    return Status::Ok();
  }
  TriangleMesh m;
  MGSR_RETURN_IF_ERROR(ReadMeshFile(o.mesh_path, &m));
  if (m.triangles.empty()) return Status::Error(o.mesh_path + ": the mesh has no faces");
  NormaliseMesh(&m, 1.0);
  if (!(m.SurfaceArea() > 0)) return Status::Error(o.mesh_path + ": the mesh has no area");
  m.vertex_colors.clear();
  m.ComputeVertexNormals();
  *mesh = std::move(m);
  return Status::Ok();
}

namespace {

// View i's focal-length factor with per_frame_focal: its own generator, so the rest of the scene
// (cameras, lights) is the same with and without it.
double PerFrameFocalScale(uint64_t seed, int view) {
  Rng rng(seed ^ (0xF0CA1ull + 7919ull * view));
  return rng.Uniform(0.85, 1.15);
}

}  // namespace

Lens SyntheticLens(const std::string& name, const Camera& c) {
  Lens l;
  l.width = c.width;
  l.height = c.height;
  l.fx = c.fx;
  l.fy = c.fy;
  l.cx = c.cx;
  l.cy = c.cy;
  if (name == "opencv") {
    // A phone-like barrel distortion with a little decentring.
    l.kind = Lens::Kind::kRadial;
    l.model = "OPENCV";
    l.k[0] = -0.3;
    l.k[1] = 0.1;
    l.p1 = 0.002;
    l.p2 = -0.0015;
  } else if (name == "fisheye") {
    l.kind = Lens::Kind::kFisheye;
    l.model = "OPENCV_FISHEYE";
    l.k[0] = -0.12;
    l.k[1] = 0.02;
    l.k[2] = -0.004;
  }
  return l;
}

Status MakeSyntheticScene(const SynthOptions& o, SyntheticScene* s) {
  MGSR_RETURN_IF_ERROR(o.Validate());
  *s = SyntheticScene();
  ParseSceneType(o.scene_type, &s->type);
  TriangleMesh object;
  MGSR_RETURN_IF_ERROR(MakeObjectMesh(o, &object));
  s->layout = MakeSceneLayout(object, s->type, o.region_half);
  Rng rng(o.seed);
  const double fx = 0.5 * o.width / std::tan(0.5 * o.fov_x);
  const double lo = std::sin(o.min_elevation_deg * kPi / 180),
               hi = std::sin(o.max_elevation_deg * kPi / 180);
  for (int i = 0; i < o.num_views; ++i) {
    // A Fibonacci spiral over the elevation band gives even coverage; a little jitter avoids
    // symmetry.
    if (s->type == SceneType::kObject) {
      const double z = lo + (hi - lo) * (i + 0.5) / o.num_views;
      const double azimuth = i * kPi * (3 - std::sqrt(5.0)) + rng.Uniform(-0.05, 0.05);
      const double r = std::sqrt(std::max(0.0, 1 - z * z));
      const double dist = o.distance * (1 + rng.Uniform(-0.03, 0.03));
      const Eigen::Vector3d center =
          dist * Eigen::Vector3d(r * std::cos(azimuth), r * std::sin(azimuth), z);
      const Eigen::Vector3d target(rng.Uniform(-0.03, 0.03), rng.Uniform(-0.03, 0.03),
                                   rng.Uniform(-0.03, 0.03));
      s->cameras.push_back(
          LookAtCamera(center, target, Eigen::Vector3d::UnitZ(), o.width, o.height, fx, fx));
    } else {
      // Once around at standing height, evenly with a little jitter.
      const double azimuth = 2 * kPi * (i + rng.Uniform(-0.2, 0.2)) / o.num_views;
      s->cameras.push_back(
          SceneOrbitCamera(s->layout, azimuth, o.distance, o.width, o.height, fx, &rng));
    }
    if (o.per_frame_focal) {
      Camera& c = s->cameras.back();
      const double f = PerFrameFocalScale(o.seed, i);
      c.fx *= f;
      c.fy *= f;
    }
    char name[32];
    std::snprintf(name, sizeof(name), "v%03d.png", i);
    s->names.push_back(name);
    s->is_test.push_back(o.test_every > 0 && i % o.test_every == 0);

    ViewLight l = FixedLight();
    if (o.varying_light) {
      const double elev = rng.Uniform(10, 80) * kPi / 180, az = rng.Uniform(0, 2 * kPi);
      l.direction = Eigen::Vector3d(std::cos(elev) * std::cos(az), std::cos(elev) * std::sin(az),
                                    std::sin(elev));
      l.intensity = rng.Uniform(0.7, 1.6);
      const int tint = static_cast<int>(rng.UniformInt(3));
      l.color = tint == 0   ? Eigen::Vector3d(1, 1, 1)
                : tint == 1 ? Eigen::Vector3d(1.0, 0.85, 0.65)
                            : Eigen::Vector3d(0.75, 0.85, 1.0);
      l.environment = rng.Uniform(0.6, 1.3);
      l.exposure_stops = rng.Uniform(-o.exposure_stops, o.exposure_stops);
    }
    s->lights.push_back(l);
  }
  return Status::Ok();
}

SyntheticRenderer::SyntheticRenderer(const SyntheticScene& scene, const SynthOptions& options)
    : scene_(scene), options_(options) {
  const SceneLayout& l = scene.layout;
  caster_ = std::make_unique<RayCaster>(l.mesh);
  if (scene.type != SceneType::kObject) {
    object_.vertices = l.mesh.vertices;
    object_.triangles.assign(l.mesh.triangles.begin(),
                             l.mesh.triangles.begin() + l.object_triangles);
    shadow_caster_ = std::make_unique<RayCaster>(object_);
  }
}

SyntheticRenderer::~SyntheticRenderer() = default;

Eigen::Vector3d SyntheticRenderer::ShadeHit(const RayHit& hit, const Eigen::Vector3d& origin,
                                            const Eigen::Vector3d& d, const ViewLight& light,
                                            bool reflections) const {
  const Eigen::Vector3d p = origin + hit.t * d;
  const Eigen::Vector3d view_dir = d.normalized();
  const RayCaster& shadows = shadow_caster_ ? *shadow_caster_ : *caster_;
  const SurfaceMaterial material = scene_.layout.materials[hit.triangle];
  if (material == SurfaceMaterial::kObject) {
    if (scene_.type == SceneType::kObject) {
      return ShadeObject(
          shadows, p, caster_->ShadingNormal(hit), view_dir, light, options_,
          [&](const Eigen::Vector3d&, const Eigen::Vector3d& r) { return Environment(r, light); });
    }
    // In a scene the mirror shows the scene: one bounce, the hit shaded without reflections.
    return ShadeObject(shadows, p, caster_->ShadingNormal(hit), view_dir, light, options_,
                       [&](const Eigen::Vector3d& from, const Eigen::Vector3d& r) {
                         RayHit bounce;
                         if (!reflections || !caster_->Intersect(from, r, 1e-6, 1e9, &bounce))
                           return Environment(r, light);
                         return ShadeHit(bounce, from, r, light, false);
                       });
  }
  Eigen::Vector3d n = caster_->ShadingNormal(hit);
  if (n.dot(view_dir) > 0) n = -n;
  return DirectLight(shadows, MaterialAlbedo(material, p, scene_.type), p, n, view_dir, light, 0.0,
                     1.0);
}

void SyntheticRenderer::Render(const Camera& cam, const ViewLight& light, Image* rgba, Image* depth,
                               Image* normal, const Lens* lens) const {
  const int w = cam.width, h = cam.height, ss = options_.supersampling;
  const bool scene_level = scene_.type != SceneType::kObject;
  const double exposure = std::pow(2.0, light.exposure_stops);
  *rgba = Image(w, h, 4);
  *depth = Image(w, h, 1);
  *normal = Image(w, h, 3);
  const Eigen::Vector3d origin = cam.Center();
  const Eigen::Matrix3d Rt = cam.R.transpose();
  // Camera-space ray (z = 1) through pixel coordinates (u, v): through the lens when there is one.
  const auto pixel_ray = [&](double u, double v) -> Eigen::Vector3d {
    if (lens == nullptr) return cam.PixelToRay(u, v);
    Eigen::Vector2d xy;
    if (!lens->Undistort({(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy}, &xy))
      return cam.PixelToRay(u, v);  // outside the model's range (not for the lenses made here)
    return {xy.x(), xy.y(), 1.0};
  };
#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      int hits = 0;
      for (int sy = 0; sy < ss; ++sy) {
        for (int sx = 0; sx < ss; ++sx) {
          // Unnormalised direction with camera-space z = 1: the hit distance t is the z-depth.
          const Eigen::Vector3d d = Rt * pixel_ray(x + (sx + 0.5) / ss, y + (sy + 0.5) / ss);
          RayHit hit;
          if (!caster_->Intersect(origin, d, 1e-9, 1e9, &hit)) {
            if (scene_level) sum += Environment(d.normalized(), light) * exposure;
            continue;
          }
          sum += ShadeHit(hit, origin, d, light, true) * exposure;
          ++hits;
        }
      }
      // Straight (not premultiplied) colour; a scene's sky fills what nothing covers.
      const int samples = scene_level ? ss * ss : hits;
      if (samples > 0) {
        sum /= samples;
        for (int c = 0; c < 3; ++c) rgba->at(c, y, x) = static_cast<float>(LinearToSrgb(sum[c]));
      }
      rgba->at(3, y, x) = scene_level ? 1.0f : static_cast<float>(hits) / (ss * ss);
      const Eigen::Vector3d d = Rt * pixel_ray(x + 0.5, y + 0.5);
      RayHit hit;
      if (caster_->Intersect(origin, d, 1e-9, 1e9, &hit)) {
        depth->at(0, y, x) = static_cast<float>(hit.t);
        Eigen::Vector3d n = caster_->ShadingNormal(hit);
        if (n.dot(d) > 0) n = -n;
        for (int c = 0; c < 3; ++c) normal->at(c, y, x) = static_cast<float>(n[c]);
      }
    }
  }
}

// The camera as the model records it: the true one, or a perturbed copy (pose_noise_*).
Camera RecordedCamera(const Camera& truth, const SynthOptions& o, Rng* rng) {
  if (o.pose_noise_deg <= 0 && o.pose_noise_rel <= 0) return truth;
  auto gaussian3 = [&](double rms) {
    // Box-Muller per axis, scaled so the vector's rms length is `rms`.
    Eigen::Vector3d v;
    for (int k = 0; k < 3; ++k) {
      const double u1 = std::max(1e-12, rng->Uniform()), u2 = rng->Uniform();
      v[k] = std::sqrt(-2 * std::log(u1)) * std::cos(2 * kPi * u2) * rms / std::sqrt(3.0);
    }
    return v;
  };
  const Eigen::Vector3d rot = gaussian3(o.pose_noise_deg * kPi / 180);
  const Eigen::Vector3d center = truth.Center() + gaussian3(o.pose_noise_rel * o.distance);
  Camera c = truth;
  if (rot.norm() > 0)
    c.R = Eigen::AngleAxisd(rot.norm(), rot.normalized()).toRotationMatrix() * c.R;
  c.t = -c.R * center;
  return c;
}

namespace {

// What a scene written here consists of: replaced whole when a scene is written over an older one,
// so no photo, mask or map of the old scene stays beside the new ones.
const char* const kSceneEntries[] = {"images",
                                     "masks",
                                     "images_constant",
                                     "sparse",
                                     "gt",
                                     "split.txt",
                                     "points3d.ply",
                                     "lights.json",
                                     "transforms_train.json",
                                     "transforms_test.json",
                                     "transforms.json"};

// An empty or missing folder takes a scene; so does an older scene of ours (it has lights.json),
// whose entries are removed first; anything else is refused, never mixed with.
Status PrepareSceneFolder(const std::string& out) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(out, ec)) return Status::Ok();
  if (!fs::is_directory(out, ec)) return Status::Error(out + ": exists and is not a folder");
  if (fs::is_empty(out, ec)) return Status::Ok();
  if (!fs::exists(JoinPath(out, "lights.json"), ec))
    return Status::Error(out +
                         ": folder is not empty and holds no scene of mgsr_synth; choose an "
                         "empty or new folder");
  for (const char* e : kSceneEntries) {
    fs::remove_all(JoinPath(out, e), ec);
    if (ec) return Status::Error(JoinPath(out, e) + ": cannot remove the older scene's file");
  }
  return Status::Ok();
}

}  // namespace

Status WriteSyntheticScene(const SynthOptions& o, const std::string& out) {
  SyntheticScene s;
  MGSR_RETURN_IF_ERROR(MakeSyntheticScene(o, &s));
  MGSR_RETURN_IF_ERROR(PrepareSceneFolder(out));
  const bool distorted = o.lens != "pinhole";
  // A lens or per-view focal lengths need nerfstudio's single json (the Blender pair has neither).
  const bool single_json = distorted || o.per_frame_focal;
  for (const char* d : {"images", "sparse/0", "gt", "gt/depth", "gt/normal"}) {
    if (distorted && std::string(d).rfind("gt/", 0) == 0) continue;
    MGSR_RETURN_IF_ERROR(MakeDirectories(JoinPath(out, d)));
  }
  std::vector<Lens> lenses;
  for (const Camera& c : s.cameras) lenses.push_back(SyntheticLens(o.lens, c));
  const bool masks = o.masks && s.type == SceneType::kObject;
  if (masks) MGSR_RETURN_IF_ERROR(MakeDirectories(JoinPath(out, "masks")));
  if (o.constant_light_copy)
    MGSR_RETURN_IF_ERROR(MakeDirectories(JoinPath(out, "images_constant")));
  const SyntheticRenderer renderer(s, o);
  const RayCaster& caster = renderer.caster();
  const TriangleMesh& mesh = s.layout.mesh;
  // A photo as the scene's views get it: with masks the render's RGBA; without, the object over a
  // plain grey background and no alpha (the constant-light copy alike, so that it can stand in
  // for images/ and is read as the same kind of scene).
  auto write_photo = [masks](const std::string& path, const Image& rgba) {
    if (masks) return WriteImage(path, rgba);
    constexpr float kBackground = 0.6f;
    Image rgb(rgba.width(), rgba.height(), 3);
    for (int c = 0; c < 3; ++c) {
      for (size_t k = 0; k < rgb.plane_size(); ++k) {
        const float a = rgba.plane(3)[k];
        rgb.plane(c)[k] = a * rgba.plane(c)[k] + (1 - a) * kBackground;
      }
    }
    return WriteImage(path, rgb);
  };

  for (size_t i = 0; i < s.cameras.size(); ++i) {
    Image rgba, depth, normal;
    renderer.Render(s.cameras[i], s.lights[i], &rgba, &depth, &normal,
                    distorted ? &lenses[i] : nullptr);
    Image mask(rgba.width(), rgba.height(), 1);
    for (size_t k = 0; k < mask.size(); ++k)
      mask.data()[k] = rgba.plane(3)[k] >= 0.5f ? 1.0f : 0.0f;
    const std::string stem = FileStem(s.names[i]);
    MGSR_RETURN_IF_ERROR(write_photo(JoinPath(out, "images/" + s.names[i]), rgba));
    if (masks) MGSR_RETURN_IF_ERROR(WriteImage(JoinPath(out, "masks/" + stem + ".png"), mask));
    if (!distorted) {
      MGSR_RETURN_IF_ERROR(WritePfm(JoinPath(out, "gt/depth/" + stem + ".pfm"), depth));
      MGSR_RETURN_IF_ERROR(WritePfm(JoinPath(out, "gt/normal/" + stem + ".pfm"), normal));
    }
    if (o.constant_light_copy) {
      renderer.Render(s.cameras[i], FixedLight(), &rgba, &depth, &normal,
                      distorted ? &lenses[i] : nullptr);
      MGSR_RETURN_IF_ERROR(write_photo(JoinPath(out, "images_constant/" + s.names[i]), rgba));
    }
  }
  MGSR_RETURN_IF_ERROR(WriteTriangleMesh(JoinPath(out, "gt/mesh.ply"), s.layout.ground_truth));
  if (s.type != SceneType::kObject) {
    const Eigen::Vector3d lo = s.layout.region.min(), hi = s.layout.region.max();
    const nlohmann::json region = {{"min", {lo.x(), lo.y(), lo.z()}},
                                   {"max", {hi.x(), hi.y(), hi.z()}},
                                   {"scene_type", o.scene_type}};
    MGSR_RETURN_IF_ERROR(WriteStringToFileAtomic(JoinPath(out, "gt/region.json"), region.dump(2)));
  }

  // COLMAP model: one shared camera (one per view with per_frame_focal; PINHOLE, or the lens's
  // OPENCV / OPENCV_FISHEYE), every view, and surface points seen by >= 2 training views with
  // exact projections (through the lens) as their observations (test views carry none).
  ColmapModel model;
  for (size_t i = 0; i < (o.per_frame_focal ? s.cameras.size() : 1); ++i) {
    const Lens& l = lenses[i];
    ColmapCamera cam;
    cam.camera_id = static_cast<uint32_t>(i + 1);
    cam.model_id = o.lens == "opencv" ? 4 : o.lens == "fisheye" ? 5 : 1;
    cam.width = o.width;
    cam.height = o.height;
    cam.params = {l.fx, l.fy, l.cx, l.cy};
    if (o.lens == "opencv") cam.params.insert(cam.params.end(), {l.k[0], l.k[1], l.p1, l.p2});
    if (o.lens == "fisheye") cam.params.insert(cam.params.end(), {l.k[0], l.k[1], l.k[2], l.k[3]});
    model.cameras.push_back(cam);
  }
  Rng pose_rng(o.seed ^ 0xBADC0DEull);
  std::vector<Camera> recorded;
  for (const Camera& c : s.cameras) recorded.push_back(RecordedCamera(c, o, &pose_rng));
  for (size_t i = 0; i < s.cameras.size(); ++i) {
    ColmapImage im;
    im.image_id = static_cast<uint32_t>(i + 1);
    im.qvec = recorded[i].RotationQuaternion();
    im.tvec = recorded[i].t;
    im.camera_id = o.per_frame_focal ? static_cast<uint32_t>(i + 1) : 1;
    im.name = s.names[i];
    model.images.push_back(im);
  }
  Rng rng(o.seed ^ 0xC0FFEEull);
  // Triangles drawn by area; in a scene each material by its share of the points (object and
  // ground half each outdoors; 40 / 40 / 20 with walls), as SfM finds texture on all of them.
  const auto area = [&](const Eigen::Vector3i& f) {
    return 0.5 * (mesh.vertices[f[1]] - mesh.vertices[f[0]])
                     .cross(mesh.vertices[f[2]] - mesh.vertices[f[0]])
                     .norm();
  };
  double scale[3] = {1, 1, 1};
  if (s.type != SceneType::kObject) {
    double material_area[3] = {0, 0, 0};
    for (size_t t = 0; t < mesh.triangles.size(); ++t)
      material_area[static_cast<int>(s.layout.materials[t])] += area(mesh.triangles[t]);
    const double share[3] = {s.type == SceneType::kIndoor ? 0.4 : 0.5,
                             s.type == SceneType::kIndoor ? 0.4 : 0.5, 0.2};
    for (int m = 0; m < 3; ++m) scale[m] = material_area[m] > 0 ? share[m] / material_area[m] : 0;
  }
  std::vector<double> cumulative;
  double total = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    total += area(mesh.triangles[t]) * scale[static_cast<int>(s.layout.materials[t])];
    cumulative.push_back(total);
  }
  TriangleMesh cloud;
  const int attempts = o.num_points * (s.type == SceneType::kObject ? 4 : 12);
  for (int attempt = 0; attempt < attempts && static_cast<int>(model.points.size()) < o.num_points;
       ++attempt) {
    const int tri = static_cast<int>(
        std::lower_bound(cumulative.begin(), cumulative.end(), rng.Uniform() * total) -
        cumulative.begin());
    const size_t picked = std::min<size_t>(tri, mesh.triangles.size() - 1);
    const auto& f = mesh.triangles[picked];
    double a = rng.Uniform(), b = rng.Uniform();
    if (a + b > 1) {
      a = 1 - a;
      b = 1 - b;
    }
    const Eigen::Vector3d X = mesh.vertices[f[0]] +
                              a * (mesh.vertices[f[1]] - mesh.vertices[f[0]]) +
                              b * (mesh.vertices[f[2]] - mesh.vertices[f[0]]);
    ColmapPoint3D p;
    p.point3D_id = model.points.size() + 1;
    p.xyz = X;
    for (size_t i = 0; i < s.cameras.size(); ++i) {
      if (s.is_test[i]) continue;
      const Camera& c = s.cameras[i];
      const Eigen::Vector3d Xc = c.WorldToCamera(X);
      if (Xc.z() <= 0.1) continue;
      const Eigen::Vector2d xy = lenses[i].Distort({Xc.x() / Xc.z(), Xc.y() / Xc.z()});
      const Eigen::Vector2d uv(c.fx * xy.x() + c.cx, c.fy * xy.y() + c.cy);
      if (uv.x() < 0 || uv.y() < 0 || uv.x() >= c.width || uv.y() >= c.height) continue;
      const Eigen::Vector3d center = c.Center();
      if (caster.Occluded(center, X - center, 1e-9, 1 - 1e-6)) continue;
      p.track_image_ids.push_back(static_cast<uint32_t>(i + 1));
      p.track_point2D_idxs.push_back(static_cast<uint32_t>(model.images[i].xys.size()));
      model.images[i].xys.push_back(uv);
      model.images[i].point3D_ids.push_back(static_cast<int64_t>(p.point3D_id));
    }
    if (p.track_image_ids.size() < 2) {  // undo the observations of a point we do not keep
      for (uint32_t id : p.track_image_ids) {
        model.images[id - 1].xys.pop_back();
        model.images[id - 1].point3D_ids.pop_back();
      }
      continue;
    }
    const Eigen::Vector3d albedo = MaterialAlbedo(s.layout.materials[picked], X, s.type);
    for (int k = 0; k < 3; ++k)
      p.rgb[k] = static_cast<uint8_t>(std::lround(255 * LinearToSrgb(albedo[k])));
    p.error = 0;
    cloud.vertices.push_back(X);
    cloud.vertex_colors.push_back(Eigen::Vector3f(p.rgb[0], p.rgb[1], p.rgb[2]) / 255.0f);
    model.points.push_back(std::move(p));
  }
  MGSR_RETURN_IF_ERROR(
      WriteColmapModel(JoinPath(out, "sparse/0"), model,
                       o.write_text_model ? ColmapFormat::kText : ColmapFormat::kBinary));
  MGSR_RETURN_IF_ERROR(WriteTriangleMesh(JoinPath(out, "points3d.ply"), cloud));

  // Split, Blender json pair and the light log.
  std::string split;
  nlohmann::json train, test, lights = nlohmann::json::array();
  for (nlohmann::json* j : {&train, &test}) {
    (*j)["camera_angle_x"] = s.cameras[0].FovX();
    (*j)["fl_x"] = s.cameras[0].fx;
    (*j)["fl_y"] = s.cameras[0].fy;
    (*j)["cx"] = s.cameras[0].cx;
    (*j)["cy"] = s.cameras[0].cy;
    (*j)["w"] = o.width;
    (*j)["h"] = o.height;
    (*j)["frames"] = nlohmann::json::array();
  }
  for (size_t i = 0; i < s.cameras.size(); ++i) {
    const std::string stem = FileStem(s.names[i]);
    if (s.is_test[i]) split += s.names[i] + "\n";
    // COLMAP world-to-camera -> OpenGL camera-to-world (y up, looking down -z).
    Eigen::Matrix4d c2w = recorded[i].WorldToCameraMatrix().inverse();
    c2w.col(1) *= -1;
    c2w.col(2) *= -1;
    nlohmann::json m = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) m.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
    nlohmann::json frame = {{"file_path", "./images/" + stem}, {"transform_matrix", m}};
    if (masks) frame["mask_path"] = "./masks/" + stem + ".png";
    (s.is_test[i] ? test : train)["frames"].push_back(frame);
    const ViewLight& l = s.lights[i];
    lights.push_back({{"name", s.names[i]},
                      {"test", static_cast<bool>(s.is_test[i])},
                      {"direction", {l.direction.x(), l.direction.y(), l.direction.z()}},
                      {"intensity", l.intensity},
                      {"color", {l.color.x(), l.color.y(), l.color.z()}},
                      {"environment", l.environment},
                      {"exposure_stops", l.exposure_stops}});
  }
  MGSR_RETURN_IF_ERROR(WriteStringToFileAtomic(JoinPath(out, "split.txt"), split));
  if (single_json) {
    // nerfstudio's transforms.json: the shared lens at the top, each frame's focal length where
    // it has its own, the split as test_filenames.
    nlohmann::json ns = train;
    ns.erase("camera_angle_x");
    const Lens& l = lenses[0];
    ns["camera_model"] = o.lens == "opencv"    ? "OPENCV"
                         : o.lens == "fisheye" ? "OPENCV_FISHEYE"
                                               : "PINHOLE";
    if (o.lens == "opencv") {
      ns["k1"] = l.k[0];
      ns["k2"] = l.k[1];
      ns["p1"] = l.p1;
      ns["p2"] = l.p2;
    } else if (o.lens == "fisheye") {
      for (int k = 0; k < 4; ++k) ns["k" + std::to_string(k + 1)] = l.k[k];
    }
    ns["frames"] = nlohmann::json::array();
    ns["test_filenames"] = nlohmann::json::array();
    size_t next_train = 0, next_test = 0;
    for (size_t i = 0; i < s.cameras.size(); ++i) {
      nlohmann::json frame =
          s.is_test[i] ? test["frames"][next_test++] : train["frames"][next_train++];
      if (o.per_frame_focal) {
        frame["fl_x"] = s.cameras[i].fx;
        frame["fl_y"] = s.cameras[i].fy;
      }
      if (s.is_test[i]) ns["test_filenames"].push_back(frame["file_path"]);
      ns["frames"].push_back(frame);
    }
    MGSR_RETURN_IF_ERROR(WriteStringToFileAtomic(JoinPath(out, "transforms.json"), ns.dump(2)));
  } else {
    MGSR_RETURN_IF_ERROR(
        WriteStringToFileAtomic(JoinPath(out, "transforms_train.json"), train.dump(2)));
    MGSR_RETURN_IF_ERROR(
        WriteStringToFileAtomic(JoinPath(out, "transforms_test.json"), test.dump(2)));
  }
  nlohmann::json info = {{"shape", o.mesh_path.empty() ? o.shape : o.mesh_path},
                         {"texture", o.texture},
                         {"seed", o.seed},
                         {"num_views", o.num_views},
                         {"width", o.width},
                         {"height", o.height},
                         {"specular", o.specular},
                         {"mirror", o.mirror},
                         {"varying_light", o.varying_light},
                         {"exposure_stops", o.exposure_stops},
                         {"pose_noise_deg", o.pose_noise_deg},
                         {"pose_noise_rel", o.pose_noise_rel},
                         {"masks", masks},
                         {"scene_type", o.scene_type},
                         {"lens", o.lens},
                         {"per_frame_focal", o.per_frame_focal},
                         {"views", lights}};
  return WriteStringToFileAtomic(JoinPath(out, "lights.json"), info.dump(2));
}

}  // namespace mgsr
