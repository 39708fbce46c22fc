// Renders of a trained solver for outputs: appearance from the 3DGS branch and geometry from the
// 2DGS branch, or both from the one branch a single-branch method trains.
#pragma once

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "solvers/mutual_boosted_solver.h"
#include "solvers/solver_options.h"

namespace mgsr {

struct Appearance {
  Image color, tran, ref, weight;
  float background = 0;
};
struct Geometry {
  Image depth, median_depth, alpha, normal_world;
};
struct ViewRender {
  Appearance appearance;
  Geometry geometry;
  Image surfel_color;  // empty unless the 2DGS branch is trained
};

// Each trained branch is rendered once; `surfel_color` keeps the 2DGS colour for meshes coloured
// by the 2DGS branch. With `geometry_only`, the 3DGS branch is rendered only when it supplies the
// geometry (a 3DGS-only method). With `transmitted_only`, the 3DGS render skips the reflected
// chain (appearance.color is then the transmitted colour; ref and weight are zero).
ViewRender RenderView(MutualBoostedSolver* solver, const SolverOptions& o, const Camera& camera,
                      bool geometry_only = false, bool transmitted_only = false);

}  // namespace mgsr
