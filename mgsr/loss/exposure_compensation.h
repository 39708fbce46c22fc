// Per-view exposure compensation as an input transform of a photometric term: the branch's colour
// is mapped by the view's affine colour model, out = A c + b, before the wrapped term compares it
// with the photo. The scene itself stays exposure-free (novel views render at a neutral exposure);
// A and b absorb what differs between photos: exposure time, gain, white balance.
//
// With a foreground mask m the model applies to the object only, out = m (A c + b) + (1 - m) c:
// the background of masked scenes is composited by us and has no exposure. Without a mask it
// applies everywhere (a real background changed exposure too).
#pragma once

#include <array>
#include <memory>
#include <string>
#include <type_traits>

#include "mgsr/loss/loss_term.h"

namespace mgsr {

enum class ExposureMode {
  kOff,       // no compensation
  kDiagonal,  // a gain and an offset per channel (6 parameters)
  kAffine,    // a full 3x3 colour matrix and offsets (12 parameters)
};
Status ParseExposureMode(const std::string& name, ExposureMode* mode);
const char* ExposureModeName(ExposureMode mode);

// A (3x3, row-major) then b (3).
using ColorTransform = std::array<double, 12>;
constexpr int kColorTransformSize = 12;
ColorTransform IdentityColorTransform();
// True for the parameters the mode optimises (diagonal: the 3 gains and 3 offsets).
bool ColorTransformParameterIsFree(ExposureMode mode, int index);

// out = m (A in + b) + (1 - m) in, per pixel; `mask` may be null (m = 1).
template <typename T>
void ApplyColorTransform(const ColorTransform& p, const ImageT<T>& in, const ImageT<T>* mask,
                         ImageT<T>* out);
// Given d out, adds d in to `d_in` (shaped like `in`) and d p to `d_params` (all 12 entries).
template <typename T>
void ColorTransformBackward(const ColorTransform& p, const ImageT<T>& in, const ImageT<T>* mask,
                            const ImageT<T>& d_out, ImageT<T>* d_in, ColorTransform* d_params);

// Wraps a photometric term on Buffer::kColor: the term sees the transformed colour. Set the view's
// transform before each Evaluate; after an Evaluate with gradients, parameter_gradient() holds
// scale * d value / d params (the term's buffer gradients go back through the transform).
class ExposureCompensatedLoss : public LossTermImpl<ExposureCompensatedLoss> {
 public:
  explicit ExposureCompensatedLoss(std::unique_ptr<LossTerm> inner,
                                   const ColorTransform& transform = IdentityColorTransform())
      : inner_(std::move(inner)), transform_(transform) {}
  std::string Name() const override { return "exposure(" + inner_->Name() + ")"; }
  std::vector<Buffer> Inputs() const override { return inner_->Inputs(); }
  std::vector<Buffer> ConstantInputs() const override { return inner_->ConstantInputs(); }
  Status Check(const RenderBuffers& in, const Targets& t) const override;

  void set_transform(const ColorTransform& p) { transform_ = p; }
  const ColorTransform& transform() const { return transform_; }
  const ColorTransform& parameter_gradient() const { return parameter_gradient_; }

  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>& t, double scale,
                 RenderGradientsT<T>* grad) const;

 private:
  std::unique_ptr<LossTerm> inner_;
  ColorTransform transform_;
  // Written by Compute (an output, like the gradient buffers).
  mutable ColorTransform parameter_gradient_{};
  // Compute's mapped colour and the inner term's gradients, kept between calls (training calls it
  // every step: no allocation once sized). One set per scalar type.
  template <typename T>
  struct Scratch {
    ImageT<T> mapped;
    RenderGradientsT<T> inner_grad;
  };
  template <typename T>
  Scratch<T>& ScratchFor() const {
    if constexpr (std::is_same_v<T, float>) {
      return scratch_float_;
    } else {
      return scratch_double_;
    }
  }
  mutable Scratch<float> scratch_float_;
  mutable Scratch<double> scratch_double_;
};

}  // namespace mgsr
