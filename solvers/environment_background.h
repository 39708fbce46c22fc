// A branch's learnt background (EnvironmentMap) with its own Adam: rendered behind the primitives
// of every view the branch renders, stepped with the branch from the gradient its renders send to
// their background (the rasterizers' *BackgroundGradient). For scene-level captures, whose sky and
// far background no primitive should have to cover (--background env).
#pragma once

#include <string>
#include <vector>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"
#include "mgsr/core/status.h"
#include "mgsr/io/binary_stream.h"
#include "mgsr/model/environment_map.h"
#include "solvers/adam.h"

namespace mgsr {

struct EnvironmentOptions {
  int width = 64, height = 32;  // texels: 5.6 degrees each
  float initial = 0.5f;         // grey
  float learning_rate = 0.01f;
};

class EnvironmentBackground {
 public:
  explicit EnvironmentBackground(const EnvironmentOptions& options);
  // The background of `camera` (3 channels).
  void Render(const Camera& camera, Image* out);
  // One Adam step from d loss / d (the background of `camera`'s render). Returns "environment"
  // when that gradient is not finite (the map is then left as it was), else "".
  std::string Step(const Camera& camera, const Image& d_background);
  // The same in two halves, for a step over a batch of views: AddGradient adds d loss / d texels
  // of one view's render into `d_texels` (sized to the map on first use); ApplyGradient steps
  // with the batch's sum.
  void AddGradient(const Camera& camera, const Image& d_background, std::vector<float>* d_texels);
  std::string ApplyGradient(std::vector<float>* d_texels);
  const EnvironmentMap& map() const { return map_; }

  // Checkpoints: the map and its Adam moments; Read checks and keeps them aside until CommitRead.
  void Save(BinaryWriter* w) const;
  Status Read(BinaryReader* r);
  void CommitRead();

 private:
  EnvironmentOptions options_;
  EnvironmentMap map_;
  EnvironmentRenderer renderer_;
  Adam adam_;
  std::vector<float> gradient_;  // scratch, the map's size
  EnvironmentMap pending_map_;
  Adam pending_adam_;
};

}  // namespace mgsr
