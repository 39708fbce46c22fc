// A learnable background for scene-level captures: a colour per viewing direction, stored as an
// equirectangular map (longitude around +z, latitude from +z down) and looked up bilinearly, for
// what no primitive covers (sky, far background). The render is linear in the texels; its
// gradient scatters each pixel's gradient to the four texels it read.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/model/param_block.h"

namespace mgsr {

// The four texels a direction reads and their bilinear weights (summing to 1).
struct EnvironmentTaps {
  int texel[4] = {0, 0, 0, 0};
  double weight[4] = {0, 0, 0, 0};
};

struct EnvironmentMap {
  int width = 0, height = 0;  // texels in longitude and latitude
  std::vector<float> texels;  // height x width rows of 3 (RGB), row-major from the +z pole

  void Reset(int w, int h, float value);
  // The taps of a unit direction: longitude wraps around, latitude clamps at the poles.
  EnvironmentTaps Taps(const Eigen::Vector3d& direction) const;
  // The colour of a direction from the given texels (any scalar type, for numeric tests).
  template <typename T>
  void Lookup(const EnvironmentTaps& taps, const std::vector<T>& values, T rgb[3]) const {
    for (int c = 0; c < 3; ++c) {
      T v = 0;
      for (int k = 0; k < 4; ++k)
        v += static_cast<T>(taps.weight[k]) * values[3 * taps.texel[k] + c];
      rgb[c] = v;
    }
  }
  std::vector<ParamBlock> Blocks() { return {{"environment", &texels, 3}}; }

  // As an image (width x height, 3 planes; row 0 at the +z pole), e.g. environment_3d.pfm of a
  // run, and back (false if the image is not a 3-channel map of 2 to 65,535 texels a side).
  Image ToImage() const;
  bool FromImage(const Image& image);
};

// The file a run keeps a branch's map in ("2d" or "3d"): environment_2d.pfm, environment_3d.pfm.
inline std::string EnvironmentFileName(const std::string& branch) {
  return "environment_" + branch + ".pfm";
}

// The taps of every pixel centre of a camera, kept while the camera stays the same (a step renders
// and back-propagates one view; a held render is the same view again). A training step at photo
// size reads them for millions of pixels, so they are computed in float with a polynomial
// arctangent (within 1e-5 rad of EnvironmentMap::Taps: a ten-thousandth of a 64-texel map's
// texel) and kept as 16 bytes a pixel; both passes run over row bands in parallel.
class EnvironmentRenderer {
 public:
  // Per pixel: the map's colour of the pixel centre's viewing direction (3 channels).
  void Render(const EnvironmentMap& map, const Camera& camera, Image* out);
  // Adds d loss / d texels for d loss / d (rendered image) `grad` into `d_texels` (sized as the
  // map's texels). The bands' sums are added in band order, so the result does not depend on
  // the number of threads.
  void Backward(const EnvironmentMap& map, const Camera& camera, const Image& grad,
                std::vector<float>* d_texels);

  // One pixel's taps (maps up to 65,535 texels a side, as FromImage accepts): the map columns x0,
  // x1 and rows y0, y1 it reads and its bilinear fractions (the weights of x1 and y1).
  struct PixelTaps {
    uint16_t x0, x1, y0, y1;
    float ax, ay;
    // The four texels read (indices of RGB triples in a map `map_width` wide) and their weights.
    void Expand(int map_width, int texel[4], float weight[4]) const {
      texel[0] = y0 * map_width + x0;
      texel[1] = y0 * map_width + x1;
      texel[2] = y1 * map_width + x0;
      texel[3] = y1 * map_width + x1;
      weight[0] = (1 - ax) * (1 - ay);
      weight[1] = ax * (1 - ay);
      weight[2] = (1 - ax) * ay;
      weight[3] = ax * ay;
    }
  };
  // The taps of every pixel (row-major), as the passes use them.
  const std::vector<PixelTaps>& TapsFor(const EnvironmentMap& map, const Camera& camera);

 private:
  Camera camera_;
  int map_width_ = 0, map_height_ = 0;
  std::vector<PixelTaps> taps_;
  std::vector<float> band_sums_;  // Backward's per-band texel gradients
};

}  // namespace mgsr
