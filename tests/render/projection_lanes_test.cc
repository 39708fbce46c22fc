// The projections run over blocks of 16 primitives (mgsr/render/projection_lanes.h): what a
// primitive gets, forward and backward, must not depend on which block or lane it falls in, nor on
// its neighbours in the block (degenerate ones included), nor on the thread count.
#include <gtest/gtest.h>

#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "mgsr/core/rng.h"
#include "mgsr/render/project_gaussians.h"
#include "mgsr/render/project_surfels.h"
#include "render_test_util.h"

namespace mgsr {
namespace {

// Every per-primitive array of a model, with the number of floats each primitive owns.
template <class Model>
std::vector<std::pair<std::vector<float>*, size_t>> Arrays(Model* m);
template <>
std::vector<std::pair<std::vector<float>*, size_t>> Arrays(SurfelModel* m) {
  const size_t k = 3 * static_cast<size_t>(m->sh_coeffs());
  return {
      {&m->means, 3}, {&m->log_scales, 2}, {&m->quats, 4}, {&m->opacity_logits, 1}, {&m->sh, k}};
}
template <>
std::vector<std::pair<std::vector<float>*, size_t>> Arrays(GaussianModel* m) {
  const size_t k = 3 * static_cast<size_t>(m->sh_coeffs());
  return {{&m->means, 3},
          {&m->log_scales, 3},
          {&m->quats, 4},
          {&m->opacity_logits, 1},
          {&m->ref_opacity_logits, 1},
          {&m->beta_logits, 1},
          {&m->sh, k},
          {&m->ref_sh, k}};
}

// Random primitives around the test camera's target, with the cases the lanes must survive: zero
// quaternions, primitives behind or beside the camera, huge and tiny scales, faint ones.
template <class Model>
Model Wild(int n, uint64_t seed) {
  Rng rng(seed);
  Model m;
  m.max_sh_degree = 3;
  m.Resize(n);
  for (auto [v, per] : Arrays(&m)) {
    for (float& x : *v) x = static_cast<float>(rng.Normal(0, 0.4));
  }
  const size_t scales = m.log_scales.size() / n;
  for (int i = 0; i < n; ++i) {
    const double u = rng.Uniform(0, 1);
    if (u < 0.1) {
      for (int k = 0; k < 4; ++k) m.quats[4 * i + k] = 0;
    } else if (u < 0.2) {
      m.means[3 * i + 1] = -4.0f;  // behind the camera (it sits at y = -3 looking along +y)
    } else if (u < 0.3) {
      m.means[3 * i] = 5.0f;  // off to the side
    }
    for (size_t k = 0; k < scales; ++k) {
      const double s = rng.Uniform(0, 1);
      m.log_scales[scales * i + k] = static_cast<float>(
          s < 0.1 ? rng.Uniform(-14, -8) : (s < 0.2 ? rng.Uniform(1, 4) : rng.Uniform(-3, -1)));
    }
    m.opacity_logits[i] = static_cast<float>(rng.Uniform(-8, 4));
  }
  return m;
}

// `m` with `shift` copies of primitive 0 in front: every original primitive moves `shift` lanes on.
template <class Model>
Model Shifted(const Model& m, int shift) {
  Model s = m;
  for (auto [v, per] : Arrays(&s)) {
    std::vector<float> prefix;
    for (int c = 0; c < shift; ++c) prefix.insert(prefix.end(), v->begin(), v->begin() + per);
    v->insert(v->begin(), prefix.begin(), prefix.end());
  }
  return s;
}

// The values of `a` for primitive i (per floats each) equal those of `b` for primitive i + shift,
// to the bit.
template <class T>
void ExpectShiftedEqual(const std::vector<T>& a, const std::vector<T>& b, size_t per, int shift,
                        const std::string& what) {
  ASSERT_EQ(a.size() + per * shift, b.size()) << what;
  EXPECT_EQ(std::memcmp(a.data(), b.data() + per * shift, a.size() * sizeof(T)), 0) << what;
}

void ExpectShiftedEqual(const std::vector<TileRect>& a, const std::vector<TileRect>& b, int shift,
                        const std::string& what) {
  ASSERT_EQ(a.size() + shift, b.size()) << what;
  for (size_t i = 0; i < a.size(); ++i) {
    const TileRect &r = a[i], &s = b[i + shift];
    EXPECT_TRUE(r.x0 == s.x0 && r.y0 == s.y0 && r.x1 == s.x1 && r.y1 == s.y1) << what << " " << i;
  }
}

// Row i of `a` (`per` floats) equals row i + shift of `b`, to the bit.
void ExpectRowShiftedEqual(const std::vector<float>& a, const std::vector<float>& b, size_t per,
                           size_t i, int shift, const std::string& what) {
  EXPECT_EQ(std::memcmp(&a[per * i], &b[per * (i + shift)], per * sizeof(float)), 0)
      << what << " " << i;
}

// Every gradient of model `b` (shifted by `shift`) equals `a`'s, to the bit.
template <class Model>
void ExpectGradientsShiftedEqual(Model a, Model b, int shift, const std::string& what) {
  const auto aa = Arrays(&a), bb = Arrays(&b);
  for (size_t k = 0; k < aa.size(); ++k)
    ExpectShiftedEqual(*aa[k].first, *bb[k].first, aa[k].second, shift, "gradient" + what);
}

// The test means something: some primitives drawn, some culled.
void ExpectSomeDrawnSomeNot(const std::vector<float>& radius) {
  int drawn = 0;
  for (float r : radius) drawn += r > 0;
  ASSERT_GT(drawn, 10);
  ASSERT_LT(drawn, static_cast<int>(radius.size()));
}

// Upstream gradients for n primitives, each entry of each array random (the same stream for a
// shifted model's originals: the prefix copies get the first primitive's values).
template <class Grad>
Grad RandomUpstream(
    size_t n, int shift, uint64_t seed,
    const std::function<std::vector<std::pair<std::vector<float>*, size_t>>(Grad*)>& arrays) {
  Grad g;
  g.ResizeAndZero(n + shift);
  Rng rng(seed);
  for (auto [v, per] : arrays(&g)) {
    for (size_t i = 0; i < n * per; ++i)
      (*v)[shift * per + i] = static_cast<float>(rng.Normal(0, 1e-2));
  }
  return g;
}

std::vector<std::pair<std::vector<float>*, size_t>> SurfelUpstream(ProjectedSurfelsGrad* g) {
  return {{&g->M, 9}, {&g->center, 2}, {&g->normal, 3}, {&g->opacity, 1}, {&g->color, 3}};
}
std::vector<std::pair<std::vector<float>*, size_t>> GaussianUpstream(ProjectedGaussiansGrad* g) {
  return {{&g->mean2d, 2},      {&g->conic, 3}, {&g->depth, 1},   {&g->opacity, 1},
          {&g->ref_opacity, 1}, {&g->beta, 1},  {&g->color_t, 3}, {&g->color_r, 3}};
}

TEST(ProjectionLanesTest, SurfelsGetTheSameWhicheverLaneTheyFallIn) {
  const Camera cam = testing::RenderTestCamera(64, 48);
  const SurfelModel m = Wild<SurfelModel>(37, 3);
  ProjectedSurfels p;
  ProjectSurfels(m, cam, 3, &p);
  const ProjectedSurfelsGrad d =
      RandomUpstream<ProjectedSurfelsGrad>(m.size(), 0, 9, SurfelUpstream);
  SurfelGradients g;
  g.ResizeAndZero(m);
  ProjectSurfelsBackward(m, cam, 3, p, d, &g);
  ASSERT_NO_FATAL_FAILURE(ExpectSomeDrawnSomeNot(p.radius));
  for (int shift : {1, 5, 15, 16, 23}) {
    const std::string what = " shift " + std::to_string(shift);
    const SurfelModel ms = Shifted(m, shift);
    ProjectedSurfels ps;
    ProjectSurfels(ms, cam, 3, &ps);
    ExpectShiftedEqual(p.M, ps.M, 9, shift, "M" + what);
    ExpectShiftedEqual(p.radius, ps.radius, 1, shift, "radius" + what);
    ExpectShiftedEqual(p.depth, ps.depth, 1, shift, "depth" + what);
    ExpectShiftedEqual(p.rects, ps.rects, shift, "rects" + what);
    for (size_t i = 0; i < m.size(); ++i) {  // the rest is written for drawn surfels only
      if (p.radius[i] <= 0) continue;
      ExpectRowShiftedEqual(p.center, ps.center, 2, i, shift, "center" + what);
      ExpectRowShiftedEqual(p.normal, ps.normal, 3, i, shift, "normal" + what);
      ExpectRowShiftedEqual(p.color, ps.color, 3, i, shift, "color" + what);
      ExpectRowShiftedEqual(p.extent, ps.extent, 2, i, shift, "extent" + what);
      ExpectRowShiftedEqual(p.opacity, ps.opacity, 1, i, shift, "opacity" + what);
      ExpectRowShiftedEqual(p.min_power, ps.min_power, 1, i, shift, "min_power" + what);
    }
    const ProjectedSurfelsGrad ds =
        RandomUpstream<ProjectedSurfelsGrad>(m.size(), shift, 9, SurfelUpstream);
    SurfelGradients gs;
    gs.ResizeAndZero(ms);
    ProjectSurfelsBackward(ms, cam, 3, ps, ds, &gs);
    ExpectGradientsShiftedEqual(g.params, gs.params, shift, what);
    ExpectShiftedEqual(g.mean2d, gs.mean2d, 2, shift, "mean2d" + what);
  }
}

TEST(ProjectionLanesTest, GaussiansGetTheSameWhicheverLaneTheyFallIn) {
  const Camera cam = testing::RenderTestCamera(64, 48);
  for (bool reflection : {true, false}) {
    const GaussianModel m = Wild<GaussianModel>(37, 5);
    ProjectedGaussians p;
    ProjectGaussians(m, cam, 3, reflection, &p);
    const ProjectedGaussiansGrad d =
        RandomUpstream<ProjectedGaussiansGrad>(m.size(), 0, 11, GaussianUpstream);
    GaussianGradients g;
    g.ResizeAndZero(m);
    ProjectGaussiansBackward(m, cam, 3, reflection, p, d, &g);
    ASSERT_NO_FATAL_FAILURE(ExpectSomeDrawnSomeNot(p.radius));
    for (int shift : {1, 7, 16, 21}) {
      const std::string what = " shift " + std::to_string(shift) + (reflection ? " refl" : "");
      const GaussianModel ms = Shifted(m, shift);
      ProjectedGaussians ps;
      ProjectGaussians(ms, cam, 3, reflection, &ps);
      ExpectShiftedEqual(p.radius, ps.radius, 1, shift, "radius" + what);
      ExpectShiftedEqual(p.depth, ps.depth, 1, shift, "depth" + what);
      ExpectShiftedEqual(p.extent, ps.extent, 2, shift, "extent" + what);
      ExpectShiftedEqual(p.min_power, ps.min_power, 1, shift, "min_power" + what);
      ExpectShiftedEqual(p.rects, ps.rects, shift, "rects" + what);
      for (size_t i = 0; i < m.size(); ++i) {
        if (p.radius[i] <= 0) continue;
        ExpectRowShiftedEqual(p.mean2d, ps.mean2d, 2, i, shift, "mean2d" + what);
        ExpectRowShiftedEqual(p.conic, ps.conic, 3, i, shift, "conic" + what);
        ExpectRowShiftedEqual(p.color_t, ps.color_t, 3, i, shift, "color_t" + what);
        ExpectRowShiftedEqual(p.view_dir, ps.view_dir, 3, i, shift, "view_dir" + what);
        ExpectRowShiftedEqual(p.opacity, ps.opacity, 1, i, shift, "opacity" + what);
        if (!reflection) continue;
        ExpectRowShiftedEqual(p.color_r, ps.color_r, 3, i, shift, "color_r" + what);
        ExpectRowShiftedEqual(p.ref_opacity, ps.ref_opacity, 1, i, shift, "ref_opacity" + what);
        ExpectRowShiftedEqual(p.beta, ps.beta, 1, i, shift, "beta" + what);
      }
      const ProjectedGaussiansGrad ds =
          RandomUpstream<ProjectedGaussiansGrad>(m.size(), shift, 11, GaussianUpstream);
      GaussianGradients gs;
      gs.ResizeAndZero(ms);
      ProjectGaussiansBackward(ms, cam, 3, reflection, ps, ds, &gs);
      ExpectGradientsShiftedEqual(g.params, gs.params, shift, what);
      ExpectShiftedEqual(g.mean2d, gs.mean2d, 2, shift, "mean2d" + what);
    }
  }
}

}  // namespace
}  // namespace mgsr
