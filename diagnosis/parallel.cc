#include <vector>

#include "diagnosis/internal.h"
#include "fitting/parallel.h"

namespace fluxcal::diag::detail {

void ParallelForModels(size_t n, const Model& m, const std::function<void(size_t, Model&)>& task) {
  std::vector<Model> own(static_cast<size_t>(std::max(1, fit::WorkersFor(n))), m);
  fit::ParallelFor(n, [&](size_t k, int worker) { task(k, own[static_cast<size_t>(worker)]); });
}

}  // namespace fluxcal::diag::detail
