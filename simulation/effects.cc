#include "simulation/effects.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

const std::vector<CatalogueEffect>& CatalogueEffects() {
  // The registry: one line per effect, in the report's order; each
  // effect's row, keys and truth in its own file under
  // simulation/catalogue/.
  static const std::vector<CatalogueEffect> all = {
      DeadTimeEffect(),          CrossSaturationEffect(),       StatorResistanceEffect(),
      HfResistanceEffect(),      DifferentialInductanceEffect(), PositionOffsetEffect(),
      CurrentSensorGainEffect(), MagnetTemperatureEffect(),     SamplingDelayEffect(),
      SpatialHarmonicsEffect(),
      // Extensions (docs/diagnosis-report.md, "Documented extensions").
      CurrentSensorOffsetEffect(), DcLinkSenseGainEffect(), PhaseResistanceImbalanceEffect(),
      StatorTemperatureDriftEffect(), InverterVoltageDropEffect(), PositionSensorHarmonicEffect(),
      IronLossEffect(), TorqueLossEffect()};
  return all;
}

void ApplyEffectsToPlant(const Effects& e, PlantModel* m) {
  for (const auto& c : CatalogueEffects()) {
    if (c.plant != nullptr) c.plant(e, m);
  }
}

const std::vector<EffectRow>& EffectCatalogue() {
  static const std::vector<EffectRow> rows = [] {
    std::vector<EffectRow> out;
    for (const auto& c : CatalogueEffects()) out.push_back(c.row);
    return out;
  }();
  return rows;
}

double AngleSensorError(const Effects& e, double theta_true_rad) {
  double error = 0.0;
  for (const auto& c : CatalogueEffects()) {
    if (c.angle_error != nullptr) error += c.angle_error(e, theta_true_rad);
  }
  return error;
}

void SenseCurrents(const Effects& e, double* ia, double* ib, double* ic) {
  for (const auto& c : CatalogueEffects()) {
    if (c.sense != nullptr) c.sense(e, ia, ib, ic);
  }
}

double TorqueReadingLoss(const Effects& e, double speed_rpm) {
  double loss = 0.0;
  for (const auto& c : CatalogueEffects()) {
    if (c.torque_loss != nullptr) loss += c.torque_loss(e, speed_rpm);
  }
  return loss;
}

const EffectRow* FindEffect(std::string_view name) {
  for (const auto& r : EffectCatalogue()) {
    if (r.name == name) return &r;
  }
  return nullptr;
}

const EffectParameter& EffectParam(std::string_view effect, std::string_view param) {
  const EffectRow* row = FindEffect(effect);
  if (row != nullptr) {
    for (const auto& p : row->parameters) {
      if (p.name == param) return p;
    }
  }
  std::fprintf(stderr, "effect catalogue: no parameter '%.*s' of effect '%.*s'\n", static_cast<int>(param.size()),
               param.data(), static_cast<int>(effect.size()), effect.data());
  std::abort();
}

namespace {

// The catalogue effect's key `key` set to v: NotFound when no catalogue
// effect owns it, InvalidArgument when the twin cannot apply v.
absl::Status SetCatalogueKey(std::string_view key, double v, Effects* e) {
  for (const auto& c : CatalogueEffects()) {
    for (const auto& k : c.keys) {
      if (k.name != key) continue;
      if (k.above ? !(v > k.min) : !(v >= k.min)) {
        return absl::InvalidArgumentError(absl::StrCat("flag --effects: field '", std::string(key), "': ", v,
                                                       " is not ", k.above ? "above " : "at least ", k.min, " (",
                                                       std::string(c.row.name), ")"));
      }
      if (k.value != nullptr) e->*k.value = v;
      else if (k.optional != nullptr) e->*k.optional = v;
      else if (k.integer != nullptr) e->*k.integer = static_cast<int>(v);
      return absl::OkStatus();
    }
  }
  return absl::NotFoundError(std::string(key));
}

}  // namespace

absl::Status ParseEffects(const std::string& spec, Effects* e, double* noise_a) {
  if (spec.empty()) return absl::OkStatus();
  for (absl::string_view item : absl::StrSplit(spec, ',', absl::SkipEmpty())) {
    std::vector<std::string> kv = absl::StrSplit(item, absl::MaxSplits('=', 1));
    if (kv.size() != 2) {
      return absl::InvalidArgumentError(absl::StrCat("flag --effects: expected key=value, got '", item, "'"));
    }
    double v;
    if (!absl::SimpleAtod(kv[1], &v) || !std::isfinite(v)) {
      return absl::InvalidArgumentError(
          absl::StrCat("flag --effects: field '", kv[0], "': expected a number, got '", kv[1], "'"));
    }
    const std::string& k = kv[0];
    if (const absl::Status set = SetCatalogueKey(k, v, e); set.ok()) {
      continue;
    } else if (!absl::IsNotFound(set)) {
      return set;
    }
    if (k == "noise_a" && noise_a != nullptr) {
      *noise_a = v;
      continue;
    }
    if (SetBenchEffectParameter(k, v, &e->unmodelled).ok()) continue;
    std::vector<std::string> known;
    for (const auto& c : CatalogueEffects()) {
      for (const auto& key : c.keys) known.push_back(std::string(key.name));
    }
    known.push_back("noise_a");
    for (const auto& x : BenchEffectParameterNames()) known.push_back(x);
    return absl::InvalidArgumentError(
        absl::StrCat("flag --effects: unknown key '", k, "' (known: ", absl::StrJoin(known, ", "), ")"));
  }
  return absl::OkStatus();
}

std::map<std::string, double> EffectParameters(const Effects& e, std::string_view effect) {
  for (const auto& c : CatalogueEffects()) {
    if (c.row.name == effect) return c.truth(e);
  }
  return {};
}

std::vector<std::string> ActiveEffectNames(const Effects& e) {
  std::vector<std::string> out;
  for (const auto& c : CatalogueEffects()) {
    bool on = false;
    if (c.active != nullptr) {
      on = c.active(e);
    } else {
      // Any catalogue parameter away from its neutral value.
      const auto values = c.truth(e);
      for (const auto& p : c.row.parameters) {
        const auto it = values.find(std::string(p.name));
        if (it != values.end() && it->second != p.neutral) on = true;
      }
    }
    if (on) out.push_back(std::string(c.row.name));
  }
  return out;
}

}  // namespace fluxcal::sim
