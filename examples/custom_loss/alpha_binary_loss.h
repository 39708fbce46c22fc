// A loss term a researcher might add: pushes each pixel's accumulated opacity towards 0 or 1
// (mean of a (1 - a)), so silhouettes become crisp. One class; main.cc registers it.
#pragma once

#include <string>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

class AlphaBinaryLoss : public mgsr::LossTermImpl<AlphaBinaryLoss> {
 public:
  std::string Name() const override { return "alpha_binary"; }
  std::vector<mgsr::Buffer> Inputs() const override { return {mgsr::Buffer::kAlpha}; }
  mgsr::Status Check(const mgsr::RenderBuffers& in, const mgsr::Targets&) const override {
    return mgsr::RequireImage(Name(), "alpha", in.Get(mgsr::Buffer::kAlpha));
  }
  // One templated body: float in training, double in gradient checks.
  template <typename T>
  double Compute(const mgsr::RenderBuffersT<T>& in, const mgsr::TargetsT<T>&, double scale,
                 mgsr::RenderGradientsT<T>* grad) const {
    const mgsr::ImageT<T>& a = *in.Get(mgsr::Buffer::kAlpha);
    const double n = static_cast<double>(a.size());
    T* g = grad != nullptr ? grad->Get(mgsr::Buffer::kAlpha, a).data() : nullptr;
    double value = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      const T x = a.data()[i];
      value += x * (1 - x) / n;
      if (g != nullptr) g[i] += static_cast<T>(scale / n) * (1 - 2 * x);  // scale * d value / d a
    }
    return value;
  }
};
