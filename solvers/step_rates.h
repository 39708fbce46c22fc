// The learning rates of one step of a branch, from the solver's options (method.md 1.8): the
// position rate's log-linear decay, the surfels' shape decay after it, and the sqrt(batch) rule.
#pragma once

#include "mgsr/loss/problem.h"
#include "solvers/learning_rates.h"
#include "solvers/solver_options.h"

namespace mgsr {

// Log-linear decay from position_lr_init to position_lr_final (times the scene's extent) over
// the branch's decay steps (SolverOptions::PositionDecaySteps); `step` counts within a stage.
double PositionLearningRate(const SolverOptions& o, Branch branch, int step, double extent);

// The factor on the 2DGS scale and rotation rates (SolverOptions::surfel_shape_decay): 1 until
// the 2DGS position rate has decayed, then the same log-linear fall over as many steps again.
double SurfelShapeRateFactor(const SolverOptions& o, int step);

// The rates of a branch's step by kind (the primitive types map their blocks onto them).
RateSchedule RatesAtStep(const SolverOptions& o, Branch branch, int step, double extent);

}  // namespace mgsr
