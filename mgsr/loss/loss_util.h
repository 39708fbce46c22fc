// Small helpers shared by the loss terms.
#pragma once

#include <string>

#include "mgsr/core/status.h"
#include "mgsr/loss/render_buffers.h"

namespace mgsr {

// Which constant image a photometric term compares against.
enum class TargetKind { kImage, kTransmitted };

template <typename T>
const ImageT<T>* SelectTarget(const TargetsT<T>& t, TargetKind kind) {
  return kind == TargetKind::kImage ? t.image : t.transmitted;
}

inline const char* TargetName(TargetKind kind) {
  return kind == TargetKind::kImage ? "image" : "transmitted";
}

// Fails unless `image` exists and, when `like` is given, has its shape.
template <typename T>
Status RequireImage(const std::string& term, const char* what, const ImageT<T>* image,
                    const ImageT<T>* like = nullptr, int channels = 0) {
  if (image == nullptr || image->empty()) return Status::Error(term + ": missing " + what);
  if (like != nullptr && (image->width() != like->width() || image->height() != like->height())) {
    return Status::Error(term + ": " + what + " size differs from the render");
  }
  if (channels > 0 && image->channels() != channels) {
    return Status::Error(term + ": " + what + " must have " + std::to_string(channels) +
                         " channel(s)");
  }
  return Status::Ok();
}

// The inputs of a term on the 2DGS geometry: the depth (1 channel), the normal (3) and the alpha
// (1) of one size, the mask when there is one, and the camera.
inline Status RequireSurfaceGeometry(const std::string& term, const RenderBuffers& in,
                                     const Targets& t) {
  const Image* depth = in.Get(Buffer::kDepth);
  MGSR_RETURN_IF_ERROR(RequireImage(term, "depth", depth, static_cast<const Image*>(nullptr), 1));
  MGSR_RETURN_IF_ERROR(RequireImage(term, "normal", in.Get(Buffer::kNormal), depth, 3));
  MGSR_RETURN_IF_ERROR(RequireImage(term, "alpha", in.Get(Buffer::kAlpha), depth, 1));
  if (t.mask != nullptr) MGSR_RETURN_IF_ERROR(RequireImage(term, "mask", t.mask, depth, 1));
  if (in.camera == nullptr) return Status::Error(term + ": needs the camera");
  return Status::Ok();
}

}  // namespace mgsr
