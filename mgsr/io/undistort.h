// Undistortion: a photo taken through a distorted lens (mgsr/core/lens.h) resampled once to the
// pinhole image the solver trains on. The maps are computed from Lens::Distort (what OpenCV's
// initUndistortRectifyMap and its fisheye variant compute; calib3d itself is not a dependency: its
// Debian package pulls in ~45 others, video and camera stacks among them) and applied with
// cv::remap (bicubic). The pinhole image has the photo's size; its intrinsics are chosen so that
// every pixel sees the photo (no blank border: OpenCV's alpha 0 / balance 0).
#pragma once

#include <string>
#include <vector>

#include "mgsr/core/image.h"
#include "mgsr/core/lens.h"
#include "mgsr/core/status.h"

namespace mgsr {

struct Undistortion {
  Lens lens;                              // the photo's
  double fx = 0, fy = 0, cx = 0, cy = 0;  // the pinhole image's (COLMAP convention), same size
  // Per pinhole pixel (row-major), where it samples the photo (OpenCV's convention: the top-left
  // pixel's centre at (0, 0)). Empty unless made with maps.
  std::vector<float> map_x, map_y;

  // "OPENCV lens (k1 -0.12, p1 0.001) undistorted to pinhole (bicubic remap), fx 1400.0 ->
  // 1310.2, ..." for the log.
  std::string Describe() const;
};

// The pinhole intrinsics for `lens` and, with `with_maps`, the resampling maps. Fails (naming
// `where`) when the lens folds over inside the photo or the result is not a usable camera.
Status MakeUndistortion(const Lens& lens, bool with_maps, const std::string& where,
                        Undistortion* out);

// Resamples every channel of `photo` (the lens's size) to the pinhole image.
Image UndistortImage(const Undistortion& u, const Image& photo);

}  // namespace mgsr
