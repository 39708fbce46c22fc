#include "solvers/view_levels.h"

#include <algorithm>
#include <cmath>

#include "mgsr/io/image_io.h"

namespace mgsr {

ViewLevel ViewLevel::FullSize(const Scene& scene, float background_2d, float background_3d) {
  ViewLevel l;
  for (const View& v : scene.views) {
    l.cameras_.push_back(v.camera);
    l.photos_.push_back(
        {CompositeOnBackground(v, background_2d), CompositeOnBackground(v, background_3d)});
    l.masks_.push_back(v.mask.empty() ? nullptr : &v.mask);
  }
  return l;
}

ViewLevel ViewLevel::Downscaled(const ViewLevel& full, int factor) {
  ViewLevel l;
  l.factor_ = full.factor_ * factor;
  const size_t n = full.size();
  l.own_masks_.resize(n);  // sized first: masks_ points into it
  for (size_t v = 0; v < n; ++v) {
    l.cameras_.push_back(CoarseCamera(full.cameras_[v], factor));
    const int w = l.cameras_.back().width, h = l.cameras_.back().height;
    l.photos_.push_back(
        {ResizeImage(full.photos_[v][0], w, h), ResizeImage(full.photos_[v][1], w, h)});
    if (full.masks_[v] != nullptr) {
      l.own_masks_[v] = ResizeImage(*full.masks_[v], w, h);
      l.masks_.push_back(&l.own_masks_[v]);
    } else {
      l.masks_.push_back(nullptr);
    }
  }
  for (int b = 0; b < 2; ++b) {
    if (full.has_grays(b)) l.MakeGrays(b);
  }
  return l;
}

void ViewLevel::MakeGrays(int branch) {
  std::vector<Image>& grays = grays_[branch];
  if (!grays.empty()) return;
  grays.resize(photos_.size());
  for (size_t v = 0; v < photos_.size(); ++v) {
    const Image& rgb = photos_[v][branch];
    Image& g = grays[v];
    g = Image(rgb.width(), rgb.height(), 1);
    for (size_t i = 0; i < g.size(); ++i)
      g.data()[i] = 0.299f * rgb.plane(0)[i] + 0.587f * rgb.plane(1)[i] + 0.114f * rgb.plane(2)[i];
  }
}

void CompositeOverMask(const Image& mask, float background, Image* image) {
  for (int c = 0; c < image->channels(); ++c) {
    float* p = image->plane(c);
    const float* m = mask.plane(0);
    for (size_t i = 0; i < image->plane_size(); ++i) {
      // Selects, not the blend, at 0 and 1: the same values as before soft masks were blended
      // (a non-finite render outside the mask stays replaced).
      p[i] = m[i] == 0.0f   ? background
             : m[i] == 1.0f ? p[i]
                            : m[i] * p[i] + (1 - m[i]) * background;
    }
  }
}

Camera CoarseCamera(const Camera& camera, int factor) {
  const auto side = [factor](int n) {
    return std::max(1, static_cast<int>(std::lround(static_cast<double>(n) / factor)));
  };
  return camera.Resized(side(camera.width), side(camera.height));
}

int CoarseFactor(const Scene& scene, int max_size) {
  if (max_size <= 0) return 1;
  int longest = 0;
  for (int v : scene.TrainIndices())
    longest = std::max({longest, scene.views[v].camera.width, scene.views[v].camera.height});
  if (longest <= max_size) return 1;
  return (longest + max_size - 1) / max_size;
}

}  // namespace mgsr
