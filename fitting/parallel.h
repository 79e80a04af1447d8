// Independent solves on the machine's cores: the fit's smoothing penalties
// (select.cc) and the diagnosis' candidate refits, profile grid and replays
// (diagnosis/parallel.cc) each run tasks that share no mutable state.
#ifndef FLUXCAL_FITTING_PARALLEL_H_
#define FLUXCAL_FITTING_PARALLEL_H_

#include <cstddef>
#include <functional>

namespace fluxcal::fit {

// Threads for independent solves: one per core, at most four.
int WorkerCount();

// task(k, worker) for k = 0..n-1 on up to min(n, WorkerCount()) threads,
// the calling thread one of them; `worker` (0 .. workers-1) names the
// thread, for scratch state of its own. Each task writes only its own
// output k, so results do not depend on the schedule.
void ParallelFor(size_t n, const std::function<void(size_t k, int worker)>& task);
// How many workers ParallelFor(n, ...) uses.
int WorkersFor(size_t n);

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_PARALLEL_H_
