#include "benchmarks/harness/suite.h"

#include <sstream>

namespace mgsr::bench {

std::vector<SceneSpec> Scenes(bool quick) {
  std::vector<SceneSpec> all = {
      {"control",
       "diffuse object under constant light (nothing to decompose)",
       {"--shape", "sphere", "--specular", "0", "--varying_light=false"},
       0,
       false},
      {"main",
       "specular highlights under light and exposure that change per view (the main case)",
       {"--shape", "torus"},
       0,
       true},
      {"exposure",
       "strong exposure swings (+-2.5 stops) on top of changing light",
       {"--shape", "sphere", "--exposure_stops", "2.5"},
       0,
       true},
      {"mirror",
       "mirror-like reflection of the environment",
       {"--shape", "rounded_box", "--mirror", "0.6"},
       0,
       true},
      {"sparse",
       "sparse views: 12 training views",
       {"--shape", "torus", "--test_every", "7"},
       14,
       true},
      {"thin", "thin structures and concavities (a rod, dents)", {"--shape", "dented"}, 0, true},
      {"noisy_poses",
       "noisy camera poses (0.5 degrees and 0.5% of the distance, rms)",
       {"--shape", "torus", "--pose_noise_deg", "0.5", "--pose_noise_rel", "0.005"},
       0,
       true},
      {"no_masks",
       "no masks: photos on a grey background, no alpha",
       {"--shape", "torus", "--masks=false"},
       0,
       true},
      {"outdoor",
       "scene-level: an object on textured ground under a sky, no masks, cameras at standing "
       "height; mesh and ground truth on the central region",
       {"--scene_type", "outdoor", "--shape", "dented"},
       0,
       true},
      {"indoor_mirror",
       "scene-level: a mirror-like object in a closed room, no masks; central region",
       {"--scene_type", "indoor", "--shape", "rounded_box", "--mirror", "0.6"},
       0,
       true},
      // Detailed shapes, 128 px: what smooth shapes cannot show (relief kept or smoothed away).
      {"gear",
       "detailed: deep trapezoidal teeth and a hole through the middle, glossy (128 px)",
       {"--shape", "gear", "--mirror", "0.3"},
       0,
       true,
       128},
      {"knot",
       "detailed: a thin tube in a trefoil knot, strands close together, glossy (128 px)",
       {"--shape", "knot", "--mirror", "0.3"},
       0,
       true,
       128},
      {"slot",
       "detailed: a block with a narrow slot 0.1 wide and 0.9 deep, glossy (128 px)",
       {"--shape", "slot", "--mirror", "0.3"},
       0,
       true,
       128},
      {"armadillo",
       "detailed: the Stanford Armadillo (deep concavities, thin ears and fingers), glossy "
       "(128 px)",
       {"--mesh", std::string(kSharedDataPrefix) + "meshes/armadillo.obj", "--mirror", "0.3"},
       0,
       true,
       128},
      {"wall",
       "a flat wall with a high-contrast print under changing light: the normal error measures "
       "texture copied into geometry (128 px)",
       {"--shape", "wall", "--texture", "print"},
       0,
       true,
       128},
  };
  if (!quick) return all;
  return {all[0], all[1]};
}

std::vector<MethodSpec> Methods(bool quick) {
  std::vector<MethodSpec> m = {
      {"mgsr",
       "MGSR: both branches, auto-stop warm-up, alternate mutual stage, affine exposure "
       "compensation",
       {},
       Coverage::kAll},
      {"2dgs", "the 2DGS branch alone (ablation B)", {"--method", "2dgs"}, Coverage::kAll},
      {"3dgs",
       "plain 3DGS alone, no reflection; mesh from its expected depth",
       {"--method", "3dgs"},
       Coverage::kAll},
      {"3dgs-ref",
       "the 3DGS branch with reflection alone (ablation A)",
       {"--method", "3dgs-ref"},
       Coverage::kAll},
  };
  if (quick) return m;
  const std::vector<MethodSpec> more = {
      {"mgsr-no-exposure",
       "MGSR without per-view exposure compensation (--exposure off)",
       {"--exposure", "off"},
       Coverage::kVaryingLight},
      {"K-bidirectional",
       "ablation K: bidirectional back-propagation",
       {"--bidirectional"},
       Coverage::kMainScene},
      {"L-no-autostop",
       "ablation L: fixed-length warm-up (no auto-stop)",
       {"--auto_stop=false"},
       Coverage::kMainScene},
      {"joint",
       "both branches every mutual iteration (the authors' code)",
       {"--mutual_mode", "joint"},
       Coverage::kMainScene},
      {"C-w3d-0.7",
       "ablation C: w_2D 0.3, w_3D 0.7",
       {"--w_2d", "0.3", "--w_3d", "0.7"},
       Coverage::kMainScene},
      {"D-w2d-0.7",
       "ablation D: w_2D 0.7, w_3D 0.3",
       {"--w_2d", "0.7", "--w_3d", "0.3"},
       Coverage::kMainScene},
      {"F-wdepth-0.1", "ablation F: w_depth 0.1", {"--w_depth", "0.1"}, Coverage::kMainScene},
      {"G-mutual-x0.25",
       "ablation G: a quarter of the mutual iterations",
       {"--mutual_iterations", "375"},
       Coverage::kMainScene},
      {"H-mutual-x0.5",
       "ablation H: half the mutual iterations",
       {"--mutual_iterations", "750"},
       Coverage::kMainScene},
      {"J-mutual-x1.5",
       "ablation J: 1.5 times the mutual iterations",
       {"--mutual_iterations", "2250"},
       Coverage::kMainScene},
  };
  m.insert(m.end(), more.begin(), more.end());
  return m;
}

Status BudgetMethods(const std::string& list, std::vector<MethodSpec>* methods) {
  methods->clear();
  std::istringstream in(list);
  for (std::string item; std::getline(in, item, ',');) {
    const auto bad = [&](const std::string& why) {
      return Status::Error("--budgets: '" + item + "' " + why);
    };
    std::string count;
    if (item == "auto") {
      count = "auto";
    } else {
      std::string digits = item;
      long long scale = 1;
      if (!digits.empty() && (digits.back() == 'k' || digits.back() == 'K')) {
        scale = 1000;
        digits.pop_back();
      }
      if (digits.empty() || digits.size() > 9 ||
          digits.find_first_not_of("0123456789") != std::string::npos)
        return bad("is not a count (like 5000 or 5k) or auto");
      const long long n = std::stoll(digits) * scale;
      if (n < 1) return bad("must be at least 1");
      count = std::to_string(n);
    }
    const std::string name = "mcmc-" + item;
    for (const MethodSpec& m : *methods) {
      if (m.name == name || m.solve_args.back() == count) return bad("is given twice");
    }
    methods->push_back({name,
                        count == "auto" ? "MCMC density, budget from the scene (--budget auto)"
                                        : "MCMC density, at most " + count + " per branch",
                        {"--density", "mcmc", "--budget", count},
                        Coverage::kAll});
  }
  if (methods->empty()) return Status::Error("--budgets: no budget given");
  methods->push_back({"reference",
                      "reference density control (clone, split, prune; scene-sized bound)",
                      {"--density", "reference"},
                      Coverage::kAll});
  return Status::Ok();
}

bool Covers(const MethodSpec& method, const SceneSpec& scene, const std::string& main_scene) {
  switch (method.coverage) {
    case Coverage::kAll:
      return true;
    case Coverage::kMainScene:
      return scene.name == main_scene;
    case Coverage::kVaryingLight:
      return scene.varying_light;
  }
  return false;
}

}  // namespace mgsr::bench
