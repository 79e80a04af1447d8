// A bench effect's parameter bookkeeping: a list of named values, on when
// any of its amplitudes is nonzero (simulation/bench_effect.h).
#ifndef FLUXCAL_SIMULATION_BENCH_EFFECTS_SIMPLE_H_
#define FLUXCAL_SIMULATION_BENCH_EFFECTS_SIMPLE_H_

#include <string_view>
#include <vector>

#include "simulation/bench_effect.h"

namespace fluxcal::sim {

class SimpleBenchEffect : public BenchEffect {
 public:
  // `amplitudes`: how many of the leading parameters switch the effect on.
  SimpleBenchEffect(std::vector<BenchEffectParameter> params, size_t amplitudes)
      : params_(std::move(params)), amplitudes_(amplitudes) {}
  std::vector<BenchEffectParameter> Parameters() const override { return params_; }
  bool Set(std::string_view name, double value) override {
    for (auto& p : params_) {
      if (p.name == name) { p.value = value; return true; }
    }
    return false;
  }
  bool Active() const override {
    for (size_t k = 0; k < amplitudes_ && k < params_.size(); ++k) {
      if (params_[k].value != 0.0) return true;
    }
    return false;
  }

 protected:
  double Value(size_t k) const { return params_[k].value; }

 private:
  std::vector<BenchEffectParameter> params_;
  size_t amplitudes_;
};

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_BENCH_EFFECTS_SIMPLE_H_
