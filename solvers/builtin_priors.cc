// The built-in primitive priors; a new one is one class and one line here (or a Register call in
// the researcher's own code).
#include "solvers/primitive_prior.h"
#include "solvers/surfel_layer_prior.h"

namespace mgsr {

void RegisterBuiltinPriors(PriorRegistry* r) { RegisterSurfelLayerPrior(r); }

}  // namespace mgsr
