#include "simulation/bench_effect.h"

#include "absl/strings/str_cat.h"

namespace fluxcal::sim {

// The registry: one line per effect, its physics in its own file under
// simulation/bench_effects/.
std::unique_ptr<BenchEffect> MakeRotorEccentricity();
std::unique_ptr<BenchEffect> MakeFluxHarmonic();
std::unique_ptr<BenchEffect> MakeEncoderEccentricity();
std::unique_ptr<BenchEffect> MakeCurrentPickup();
std::unique_ptr<BenchEffect> MakeCurrentCrosstalk();
std::unique_ptr<BenchEffect> MakeDcLinkRipple();
std::unique_ptr<BenchEffect> MakePartialDemagnetisation();

std::vector<std::unique_ptr<BenchEffect>> AllBenchEffects() {
  std::vector<std::unique_ptr<BenchEffect>> all;
  all.push_back(MakeRotorEccentricity());
  all.push_back(MakeFluxHarmonic());
  all.push_back(MakeEncoderEccentricity());
  all.push_back(MakeCurrentPickup());
  all.push_back(MakeCurrentCrosstalk());
  all.push_back(MakeDcLinkRipple());
  all.push_back(MakePartialDemagnetisation());
  return all;
}

absl::Status SetBenchEffectParameter(const std::string& key, double value, BenchEffects* effects) {
  for (auto& existing : *effects) {
    for (const auto& p : existing->Parameters()) {
      if (p.name != key) continue;
      // Copy on write: the effect objects are shared between configs.
      auto copy = AllBenchEffects();
      for (auto& fresh : copy) {
        if (fresh->Name() != existing->Name()) continue;
        for (const auto& q : existing->Parameters()) fresh->Set(q.name, q.value);
        fresh->Set(key, value);
        existing = std::shared_ptr<const BenchEffect>(std::move(fresh));
        return absl::OkStatus();
      }
    }
  }
  for (auto& fresh : AllBenchEffects()) {
    if (fresh->Set(key, value)) {
      effects->push_back(std::shared_ptr<const BenchEffect>(std::move(fresh)));
      return absl::OkStatus();
    }
  }
  return absl::NotFoundError(absl::StrCat("no bench effect has a parameter '", key, "'"));
}

std::vector<std::string> BenchEffectParameterNames() {
  std::vector<std::string> out;
  for (const auto& e : AllBenchEffects()) {
    for (const auto& p : e->Parameters()) out.push_back(std::string(p.name));
  }
  return out;
}

}  // namespace fluxcal::sim
