// Closed-form-style initial estimate of a view's colour transform: a small robust least-squares
// problem (Huber loss, so highlights and other things the transform cannot explain do not drag
// the fit), photo ~ A render + b over the foreground pixels, solved by iteratively reweighted
// least squares (a few 4x4 solves; Ceres with a residual block per pixel took ~60 ms a view). The
// solver runs it for every training view at the start of the mutual stage, against the warmed-up
// render.
#pragma once

#include "mgsr/core/image.h"
#include "mgsr/core/status.h"
#include "mgsr/loss/exposure_compensation.h"

namespace mgsr {

struct ExposureFitOptions {
  ExposureMode mode = ExposureMode::kDiagonal;
  double huber_delta = 0.05;    // residuals beyond this (in [0, 1] colour units) count linearly
  int max_samples = 8000;       // pixels used (an even stride over the foreground)
  float mask_threshold = 0.5f;  // foreground: mask above this
  float saturation = 0.99f;  // photo pixels at or above this in any channel are clipped: left out
  // Offsets cost offset_prior * samples * |b|^2: an exposure change is a gain; a free offset
  // trades against the gain wherever the render is imperfect and biases it.
  double offset_prior = 1.0;
};

struct ExposureFitSummary {
  int samples = 0;
  double initial_cost = 0, final_cost = 0;
};

// Fits `out` (the free parameters of the mode; the rest stay at identity) so that
// A render + b matches `photo`. `mask` may be null (every pixel is foreground). Fails when fewer
// than 16 usable pixels remain or the sizes differ.
Status FitColorTransform(const Image& render, const Image& photo, const Image* mask,
                         const ExposureFitOptions& options, ColorTransform* out,
                         ExposureFitSummary* summary = nullptr);

}  // namespace mgsr
