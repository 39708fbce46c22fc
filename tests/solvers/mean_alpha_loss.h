// A small loss term for tests that add a row to the loss table: the mean of the 2DGS alpha, with
// its gradient. Registered by the tests that use it; being registered, it must also pass the
// gradient harness of tests/loss/loss_test.cc (which checks every registered term).
#pragma once

#include <string>
#include <vector>

#include "mgsr/loss/loss_term.h"
#include "mgsr/loss/loss_util.h"

namespace mgsr {
namespace testing {

class MeanAlphaLoss : public LossTermImpl<MeanAlphaLoss> {
 public:
  std::string Name() const override { return "test_mean_alpha"; }
  std::vector<Buffer> Inputs() const override { return {Buffer::kAlpha}; }
  Status Check(const RenderBuffers& in, const Targets&) const override {
    return RequireImage(Name(), "alpha", in.Get(Buffer::kAlpha));
  }
  template <typename T>
  double Compute(const RenderBuffersT<T>& in, const TargetsT<T>&, double scale,
                 RenderGradientsT<T>* grad) const {
    const ImageT<T>& a = *in.Get(Buffer::kAlpha);
    double sum = 0;
    for (size_t i = 0; i < a.size(); ++i) sum += a.data()[i];
    if (grad != nullptr) {
      T* g = grad->Get(Buffer::kAlpha, a).data();
      for (size_t i = 0; i < a.size(); ++i) g[i] += static_cast<T>(scale / a.size());
    }
    return sum / a.size();
  }
};

}  // namespace testing
}  // namespace mgsr
