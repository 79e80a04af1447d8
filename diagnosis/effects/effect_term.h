// The catalogue's effects on the diagnosis' side, one file per effect
// under diagnosis/effects/ (registered in diagnosis/effects/registry.cc,
// in the report's order): the candidate refits that free its parameter
// blocks (Block, internal.h; their scales are the catalogue's fit_scale),
// when the set can test it, the finding's parameters in the catalogue's
// names and units with their standard deviations, its share of the twin's
// replay, and whether the diagnosed calibration's data are freed of it.
// The catalogue row itself is the twin's side of the same effect
// (simulation/catalogue/); the observation terms are the Model's
// (internal.h), which composes the effects in one forward model.
#ifndef FLUXCAL_DIAGNOSIS_EFFECTS_EFFECT_TERM_H_
#define FLUXCAL_DIAGNOSIS_EFFECTS_EFFECT_TERM_H_

#include <string>
#include <string_view>
#include <vector>

#include "diagnosis/internal.h"

namespace fluxcal::diag::detail {

struct EffectTerm {
  std::string_view effect;   // the catalogue's name
  // The refits that try it (one per block set; spatial_harmonics one per
  // order, magnet_temperature's drift beside its mean).
  std::vector<Candidate> candidates;
  // Whether the set can test candidate c (nullptr: always).
  bool (*testable)(const Candidate& c, const Model& m) = nullptr;
  // The finding's parameters and their standard deviations (and any
  // alternative explanation) from the fit f, whose parameter blocks p are;
  // `out` has its effect and explanation set.
  void (*describe)(const Candidate& c, const Model& m, const FitOut& f, const double* const* p,
                   Finding* out) = nullptr;
  // Its share of the twin's open-loop replay at the model's parameters p
  // (evidence.cc); nullptr: the replay's surfaces carry it (psi_pm) or
  // the replay never shows it (torque, a drift).
  void (*replay)(const Model& m, const double* const* p, int harm_order, sim::ReplayOptions* opt) = nullptr;
  // The blocks the diagnosed calibration's data are freed of
  // (CorrectedFitData): a bench's artefacts, not a motor property such as
  // Rs or the mean psi_pm.
  std::vector<Block> artefact_blocks;
};

// A term whose one candidate frees its one block (most effects); its data
// freed of it in the diagnosed calibration unless it is a motor property
// (`artefact` false: stator_resistance).
inline EffectTerm OneBlockTerm(std::string_view effect, Block block, bool artefact = true) {
  EffectTerm t;
  t.effect = effect;
  t.candidates = {{std::string(effect), block}};
  if (artefact) t.artefact_blocks = {block};
  return t;
}

// Every effect diagnosis can name, in the report's order.
const std::vector<EffectTerm>& EffectTerms();
// The term of `effect`, or nullptr.
const EffectTerm* FindTerm(std::string_view effect);

// Helpers of the describe functions: the standard deviation of block b's
// element i (0 when the fit did not estimate it), and a parameter with
// its standard deviation under one name.
inline double Sd(const FitOut& f, Block b, int i) {
  const auto it = f.stdev.find(b);
  return it == f.stdev.end() ? 0.0 : it->second[i];
}
inline void SetParam(Finding* out, const std::string& name, double value, double stdev) {
  out->parameters[name] = value;
  out->parameter_std[name] = stdev;
}

// One per file under diagnosis/effects/.
EffectTerm DeadTimeTerm();
EffectTerm StatorResistanceTerm();
EffectTerm HfResistanceTerm();
EffectTerm PositionOffsetTerm();
EffectTerm CurrentSensorGainTerm();
EffectTerm MagnetTemperatureTerm();
EffectTerm SamplingDelayTerm();
EffectTerm SpatialHarmonicsTerm();
EffectTerm CurrentSensorOffsetTerm();
EffectTerm DcLinkSenseGainTerm();
EffectTerm PhaseResistanceImbalanceTerm();
EffectTerm StatorTemperatureDriftTerm();
EffectTerm InverterVoltageDropTerm();
EffectTerm PositionSensorHarmonicTerm();
EffectTerm IronLossTerm();
EffectTerm TorqueLossTerm();

}  // namespace fluxcal::diag::detail

#endif  // FLUXCAL_DIAGNOSIS_EFFECTS_EFFECT_TERM_H_
