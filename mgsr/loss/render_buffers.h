// What loss terms read and write: the named buffers of a branch's render, constant targets, and
// the gradients with respect to the buffers. Templated on the scalar type: float in training,
// double for gradient checks.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>

#include "mgsr/core/camera.h"
#include "mgsr/core/image.h"

namespace mgsr {

enum class Buffer {
  kColor,        // the branch's colour (3DGS: C = C_tran + W C_ref; 2DGS: C)
  kTransmitted,  // 3DGS C_tran
  kReflected,    // 3DGS C_ref
  kWeight,       // 3DGS W
  kDepth,        // expected depth (both branches)
  kAlpha,        // accumulated opacity
  kNormal,       // 2DGS alpha-weighted world-space normal
  kMedianDepth,  // 2DGS
  kDistortion,   // 2DGS
  kCount
};
constexpr int kNumBuffers = static_cast<int>(Buffer::kCount);
// A set of buffers, bit b for Buffer b (e.g. what a render must produce).
using BufferSet = uint32_t;
constexpr BufferSet BufferBit(Buffer b) { return 1u << static_cast<int>(b); }
constexpr BufferSet kAllBuffers = (1u << kNumBuffers) - 1;
const char* BufferName(Buffer b);
// Channels of each buffer (3 for colours and normals, else 1).
int BufferChannels(Buffer b);

template <typename T>
struct RenderBuffersT {
  std::array<const ImageT<T>*, kNumBuffers> images{};
  const Camera* camera = nullptr;  // needed by geometric terms (depth to normal)

  const ImageT<T>* Get(Buffer b) const { return images[static_cast<int>(b)]; }
  void Set(Buffer b, const ImageT<T>* image) { images[static_cast<int>(b)] = image; }
};

// A neighbouring view, for terms that compare several views (multi-view consistency): its camera,
// its photo in grey, and, when a row asks for it, its depth rendered by the same branch with the
// current parameters. All constants.
template <typename T>
struct NeighbourViewT {
  const Camera* camera = nullptr;
  const ImageT<T>* gray = nullptr;   // 1 channel, the photo on the branch's background
  const ImageT<T>* depth = nullptr;  // 1 channel; null unless a row reads neighbour depth
};
// At most this many neighbours per view (a fixed array: targets are copied every step).
constexpr int kMaxNeighbours = 4;

// Constant inputs: nothing here receives a gradient (that is one-way supervision).
template <typename T>
struct TargetsT {
  const ImageT<T>* image = nullptr;  // ground truth, RGB
  const ImageT<T>* mask = nullptr;   // foreground weight gamma in [0, 1], 1 channel
  const ImageT<T>* transmitted =
      nullptr;  // the 3DGS branch's C_tran, as a target for the 2DGS branch
  const ImageT<T>* other_depth =
      nullptr;  // the 2DGS branch's depth, as a target for the 3DGS branch
  // Multi-view terms: this view's photo in grey and its neighbours (chosen once per scene,
  // SelectNeighbours in mgsr/io/view_neighbours.h).
  const ImageT<T>* gray = nullptr;
  std::array<NeighbourViewT<T>, kMaxNeighbours> neighbours{};
  int num_neighbours = 0;
};

template <typename T>
struct RenderGradientsT {
  std::array<ImageT<T>, kNumBuffers> images;

  // The gradient image of `b`, created as zeros shaped like `like` on first use (in the storage
  // it kept from earlier use).
  ImageT<T>& Get(Buffer b, const ImageT<T>& like) {
    ImageT<T>& g = images[static_cast<int>(b)];
    if (!g.SameShape(like)) g.Reset(like.width(), like.height(), like.channels());
    return g;
  }
  const ImageT<T>& Get(Buffer b) const { return images[static_cast<int>(b)]; }
  // Every image empty (zero gradient), their storage kept.
  void Clear() {
    for (auto& im : images) im.Clear();
  }
};

// The targets that are the other branch's renders: what bidirectional supervision differentiates.
enum class OtherBranchTarget {
  kTransmitted,  // Targets::transmitted (the 3DGS C_tran, for the 2DGS branch)
  kDepth,        // Targets::other_depth (the 2DGS depth, for the 3DGS branch)
};

// Gradients with respect to those targets (empty until a term adds to them).
template <typename T>
struct TargetGradientsT {
  ImageT<T> transmitted, other_depth;

  // Adds `g` into the gradient of `target` (moved in when that is still empty).
  void Add(OtherBranchTarget target, ImageT<T> g) {
    ImageT<T>& into = target == OtherBranchTarget::kTransmitted ? transmitted : other_depth;
    if (into.empty()) {
      into = std::move(g);
      return;
    }
    for (size_t i = 0; i < into.size(); ++i) into.data()[i] += g.data()[i];
  }
};

using RenderBuffers = RenderBuffersT<float>;
using RenderBuffersD = RenderBuffersT<double>;
using NeighbourView = NeighbourViewT<float>;
using Targets = TargetsT<float>;
using TargetsD = TargetsT<double>;
using RenderGradients = RenderGradientsT<float>;
using RenderGradientsD = RenderGradientsT<double>;
using TargetGradients = TargetGradientsT<float>;
using TargetGradientsD = TargetGradientsT<double>;

}  // namespace mgsr
