#include "fitting/parallel.h"

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

namespace fluxcal::fit {

int WorkerCount() {
  // CPU-bound and independent: one worker per core; beyond four the
  // serial parts around them dominate (seven penalties, ~20 candidates).
  const unsigned hw = std::thread::hardware_concurrency();
  return static_cast<int>(std::clamp(hw == 0 ? 1u : hw, 1u, 4u));
}

int WorkersFor(size_t n) { return static_cast<int>(std::min<size_t>(n, static_cast<size_t>(WorkerCount()))); }

void ParallelFor(size_t n, const std::function<void(size_t, int)>& task) {
  const int workers = WorkersFor(n);
  if (workers <= 1) {
    for (size_t k = 0; k < n; ++k) task(k, 0);
    return;
  }
  std::atomic<size_t> next{0};
  auto work = [&](int worker) {
    for (size_t k = next++; k < n; k = next++) task(k, worker);
  };
  std::vector<std::thread> pool;
  pool.reserve(static_cast<size_t>(workers - 1));
  for (int w = 1; w < workers; ++w) pool.emplace_back(work, w);
  work(0);
  for (auto& t : pool) t.join();
}

}  // namespace fluxcal::fit
