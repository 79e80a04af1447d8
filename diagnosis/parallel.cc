#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

#include "diagnosis/internal.h"

namespace fluxcal::diag::detail {

int WorkerCount() {
  // The refits are CPU-bound and independent: one worker per core, at most
  // four (the candidate rounds hold ~20 refits; beyond four cores the
  // serial parts dominate).
  const unsigned hw = std::thread::hardware_concurrency();
  return static_cast<int>(std::clamp(hw == 0 ? 1u : hw, 1u, 4u));
}

void ParallelFor(size_t n, const std::function<void(size_t)>& task) {
  const size_t workers = std::min<size_t>(n, static_cast<size_t>(WorkerCount()));
  if (workers <= 1) {
    for (size_t k = 0; k < n; ++k) task(k);
    return;
  }
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t k = next++; k < n; k = next++) task(k);
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (size_t w = 1; w < workers; ++w) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
}

void ParallelForModels(size_t n, const Model& m, const std::function<void(size_t, Model&)>& task) {
  const size_t workers = std::min<size_t>(n, static_cast<size_t>(WorkerCount()));
  if (workers <= 1) {
    Model own = m;
    for (size_t k = 0; k < n; ++k) task(k, own);
    return;
  }
  std::atomic<size_t> next{0};
  auto work = [&] {
    Model own = m;
    for (size_t k = next++; k < n; k = next++) task(k, own);
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (size_t w = 1; w < workers; ++w) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
}

}  // namespace fluxcal::diag::detail
