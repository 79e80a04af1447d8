// Physics the twin's bench can carry that the diagnosis' catalogue does not
// (docs/diagnosis.md, "Honesty"): each effect one file under
// simulation/bench_effects/, registered in bench_effect.cc. The twin applies
// it through the hooks below; diagnosis never models it, so a set that
// carries one tests that the mismatch is located and left unexplained,
// never `explained` by catalogue effects that are not there.
//
// Angles: th_e the true electrical angle of the rotor d axis, th_m the
// true mechanical angle, th_m = (th_e + 2 pi sector) / pole pairs with
// `sector` the pole pair the rotor stands in (PlanPoint::sector).
#ifndef FLUXCAL_SIMULATION_BENCH_EFFECT_H_
#define FLUXCAL_SIMULATION_BENCH_EFFECT_H_

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"

namespace fluxcal::sim {

struct BenchEffectParameter {
  std::string_view name;      // --effects key, unique across all effects, unit suffix
  std::string_view unit;
  double value = 0.0;         // default (an amplitude's default is 0: off)
  std::string_view meaning;
};

class BenchEffect {
 public:
  virtual ~BenchEffect() = default;
  virtual std::string_view Name() const = 0;
  virtual std::string_view Meaning() const = 0;
  // The parameters with their current values.
  virtual std::vector<BenchEffectParameter> Parameters() const = 0;
  // Sets a parameter by name; false when the effect has no such parameter.
  virtual bool Set(std::string_view name, double value) = 0;
  // On when any amplitude is nonzero.
  virtual bool Active() const = 0;

  // Hooks (the default does nothing).
  // The magnetics at the true angles: the machine's flux linkage and, when
  // the pointers are given, its differential inductance (true dq frame),
  // modified in place; psi_pm_wb is the machine's flux at zero current.
  virtual void ModifyMagnetics(double /*th_e*/, double /*th_m*/, double /*psi_pm_wb*/, double* /*psi_d*/,
                               double* /*psi_q*/, double* /*ldd*/, double* /*lqq*/, double* /*ldq*/) const {}
  // The phase currents the sensors report at time t, from what they would
  // report without the effect.
  virtual void Sense(double /*t_s*/, double* /*ia*/, double* /*ib*/, double* /*ic*/) const {}
  // Error the angle sensor adds at the true angles.
  virtual double AngleError(double /*th_e*/, double /*th_m*/) const { return 0.0; }
  // The DC-link voltage the inverter applies at time t over its mean (what
  // the measurement and so the modulator see).
  virtual double UdcFactor(double /*t_s*/) const { return 1.0; }
};

using BenchEffects = std::vector<std::shared_ptr<const BenchEffect>>;

// Fresh instances of every registered bench effect, all off.
std::vector<std::unique_ptr<BenchEffect>> AllBenchEffects();
// Sets parameter `key` on the bench effect that owns it, creating that
// effect in `effects` when absent; NotFound when no bench effect has it.
absl::Status SetBenchEffectParameter(const std::string& key, double value, BenchEffects* effects);
// Every bench-effect parameter name (for messages listing known keys).
std::vector<std::string> BenchEffectParameterNames();

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_BENCH_EFFECT_H_
