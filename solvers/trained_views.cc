#include "solvers/trained_views.h"

#include "mgsr/loss/normal_consistency_loss.h"

namespace mgsr {

ViewRender RenderView(MutualBoostedSolver* solver, const SolverOptions& o, const Camera& camera,
                      bool geometry_only, bool transmitted_only) {
  ViewRender out;
  if (o.train_2d) {
    SurfelRender sr;
    solver->RenderSurfels(camera, &sr, /*distortion=*/false);
    const float bg = o.background_2d;
    if (!o.train_3d) {
      const int w = sr.color.width(), h = sr.color.height();
      out.appearance = {sr.color, sr.color, Image(w, h, 3), Image(w, h, 1), bg};
    }
    out.surfel_color = std::move(sr.color);
    out.geometry = {std::move(sr.depth), std::move(sr.median_depth), std::move(sr.alpha),
                    std::move(sr.normal_world)};
  }
  if (o.train_3d && !(geometry_only && o.train_2d)) {
    GaussianRender g;
    solver->RenderGaussians(camera, &g, !transmitted_only);
    if (!o.train_2d) {
      // 3DGS geometry: expected depth (no median), normals from the depth where it is opaque.
      Image normal = DepthToNormal(g.depth, camera);
      for (size_t k = 0; k < g.alpha.size(); ++k) {
        if (g.alpha.data()[k] < 0.5f) {
          for (int c = 0; c < 3; ++c) normal.plane(c)[k] = 0;
        }
      }
      out.geometry = {g.depth, std::move(g.depth), std::move(g.alpha), std::move(normal)};
    }
    out.appearance = {std::move(g.color), std::move(g.tran), std::move(g.ref), std::move(g.weight),
                      o.background_3d};
  }
  return out;
}

}  // namespace mgsr
