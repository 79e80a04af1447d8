#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

const std::vector<EffectTerm>& EffectTerms() {
  // The registry: one line per effect, in the report's order (the
  // catalogue's cross_saturation is the baseline's magnetics and
  // differential_inductance a calibration tool's error: neither is a
  // block of the model).
  static const std::vector<EffectTerm> all = {
      DeadTimeTerm(),          StatorResistanceTerm(),        HfResistanceTerm(),
      PositionOffsetTerm(),    CurrentSensorGainTerm(),       MagnetTemperatureTerm(),
      SamplingDelayTerm(),     SpatialHarmonicsTerm(),        CurrentSensorOffsetTerm(),
      DcLinkSenseGainTerm(),   PhaseResistanceImbalanceTerm(), StatorTemperatureDriftTerm(),
      InverterVoltageDropTerm(), PositionSensorHarmonicTerm(), IronLossTerm(),
      TorqueLossTerm()};
  return all;
}

const EffectTerm* FindTerm(std::string_view effect) {
  for (const auto& t : EffectTerms()) {
    if (t.effect == effect) return &t;
  }
  return nullptr;
}

}  // namespace fluxcal::diag::detail
