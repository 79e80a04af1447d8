#include <atomic>
#include <vector>

#include "diagnosis/internal.h"
#include "fitting/parallel.h"

namespace fluxcal::diag::detail {

bool ParallelForModels(size_t n, const Model& m, const std::function<void(size_t, Model&)>& task,
                       const std::function<bool()>& cancelled) {
  std::vector<Model> own(static_cast<size_t>(std::max(1, fit::WorkersFor(n))), m);
  std::atomic<bool> stop{false};
  fit::ParallelFor(n, [&](size_t k, int worker) {
    // Polled on the calling thread only (worker 0): the caller's callback
    // need not be thread-safe; once it says stop, no task starts.
    if (worker == 0 && cancelled && cancelled()) stop = true;
    if (stop) return;
    task(k, own[static_cast<size_t>(worker)]);
  });
  return stop;
}

}  // namespace fluxcal::diag::detail
