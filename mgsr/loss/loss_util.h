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

}  // namespace mgsr
