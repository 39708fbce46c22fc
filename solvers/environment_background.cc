#include "solvers/environment_background.h"

#include <algorithm>

#include "solvers/checkpoint_io.h"

namespace mgsr {

EnvironmentBackground::EnvironmentBackground(const EnvironmentOptions& options)
    : options_(options) {
  map_.Reset(options.width, options.height, options.initial);
}

void EnvironmentBackground::Render(const Camera& camera, Image* out) {
  renderer_.Render(map_, camera, out);
}

std::string EnvironmentBackground::Step(const Camera& camera, const Image& d_background) {
  gradient_.assign(map_.texels.size(), 0.0f);
  AddGradient(camera, d_background, &gradient_);
  return ApplyGradient(&gradient_);
}

void EnvironmentBackground::AddGradient(const Camera& camera, const Image& d_background,
                                        std::vector<float>* d_texels) {
  renderer_.Backward(map_, camera, d_background, d_texels);
}

std::string EnvironmentBackground::ApplyGradient(std::vector<float>* d_texels) {
  if (!AllFinite(*d_texels)) return "environment";  // the caller stops; the map stays as it was
  const float rate = options_.learning_rate;
  const std::string bad =
      adam_.Step(map_.Blocks(), {{"environment", d_texels, 3}},
                 [rate](const std::string&, int width, std::vector<float>* rates) {
                   rates->assign(width, rate);
                 });
  // Colours stay displayable: the map is what the photos show where nothing else is.
  for (float& v : map_.texels) v = std::clamp(v, 0.0f, 1.0f);
  return bad;
}

void EnvironmentBackground::Save(BinaryWriter* w) const {
  w->Write<int32_t>(map_.width);
  w->Write<int32_t>(map_.height);
  WriteVector(w, map_.texels);
  WriteAdamState(w, adam_);
}

Status EnvironmentBackground::Read(BinaryReader* r) {
  int32_t width = 0, height = 0;
  MGSR_RETURN_IF_ERROR(r->Read(&width));
  MGSR_RETURN_IF_ERROR(r->Read(&height));
  if (width != options_.width || height != options_.height) {
    return Status::Error(r->path() + ": the checkpoint's environment map is " +
                         std::to_string(width) + "x" + std::to_string(height) + ", this run's " +
                         std::to_string(options_.width) + "x" + std::to_string(options_.height));
  }
  pending_map_.width = width;
  pending_map_.height = height;
  MGSR_RETURN_IF_ERROR(ReadVector(r, &pending_map_.texels));
  if (pending_map_.texels.size() != static_cast<size_t>(width) * height * 3 ||
      !AllFinite(pending_map_.texels))
    return Status::Error(r->path() + ": corrupt checkpoint (environment map)");
  return ReadAdamState(r, &pending_adam_);
}

void EnvironmentBackground::CommitRead() {
  map_ = std::move(pending_map_);
  adam_ = std::move(pending_adam_);
  pending_map_ = EnvironmentMap();
  pending_adam_ = Adam();
}

}  // namespace mgsr
