// What the solver's steps read of each view (camera, photo on each branch's background, mask,
// photo in grey for the multi-view terms) at one resolution: the scene's, or a coarser one that
// the first part of each stage trains on (SolverOptions::coarse_factor). At photo size most of
// an iteration is per pixel (docs/performance.md), so a level at half the size costs about a
// quarter; the models it trains are the same models, rendered through the downscaled cameras.
#pragma once

#include <array>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/io/scene.h"

namespace mgsr {

class ViewLevel {
 public:
  ViewLevel() = default;
  ViewLevel(ViewLevel&&) = default;  // (a moved vector keeps its elements: the mask pointers hold)
  ViewLevel& operator=(ViewLevel&&) = default;
  ViewLevel(const ViewLevel&) = delete;
  ViewLevel& operator=(const ViewLevel&) = delete;
  // The scene's own size: its cameras and masks (borrowed: `scene` must outlive the level), each
  // photo composited on each branch's background (index 0 the 2DGS branch, 1 the 3DGS branch).
  static ViewLevel FullSize(const Scene& scene, float background_2d, float background_3d);
  // `full` with every view divided by `factor` (each side rounded, at least 1 px): cameras through
  // Camera::Resized, photos, greys and masks area-averaged.
  static ViewLevel Downscaled(const ViewLevel& full, int factor);

  int factor() const { return factor_; }
  size_t size() const { return cameras_.size(); }
  const Camera& camera(int view) const { return cameras_[view]; }
  const Image& photo(int view, int branch) const { return photos_[view][branch]; }
  // Null where the view has no mask.
  const Image* mask(int view) const { return masks_[view]; }
  // Every photo of `branch` in grey (Rec. 601 luma), made once; empty until then.
  void MakeGrays(int branch);
  bool has_grays(int branch) const { return !grays_[branch].empty(); }
  const Image& gray(int view, int branch) const { return grays_[branch][view]; }

 private:
  int factor_ = 1;
  std::vector<Camera> cameras_;
  std::vector<std::array<Image, 2>> photos_;
  std::vector<Image> own_masks_;     // the downscaled masks (a full level borrows the scene's)
  std::vector<const Image*> masks_;  // per view, into own_masks_ or the scene
  std::array<std::vector<Image>, 2> grays_;
};

// Each pixel of `image` (every channel) becomes mask x image + (1 - mask) x background: the image
// where the mask holds the object, the background where it does not, and on a soft edge (a mask
// area-averaged to a coarse level or resized with its photo) their mixture, as a photo's pixel
// on the edge mixes the two. On a binary mask the pixels are kept or replaced exactly.
void CompositeOverMask(const Image& mask, float background, Image* image);

// `camera` divided by `factor`: each side rounded, at least 1 px (Camera::Resized).
Camera CoarseCamera(const Camera& camera, int factor);

// The factor of the coarse level: the smallest integer that brings the longest side of any
// training view to at most `max_size` px; 1 (no coarse level) when they already fit or when
// max_size is 0.
int CoarseFactor(const Scene& scene, int max_size);

}  // namespace mgsr
