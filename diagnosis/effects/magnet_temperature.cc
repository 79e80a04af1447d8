// magnet_temperature on the diagnosis' side (effect_term.h): block kPsi
// (psi_pm relative to nominal, Model::PsiPm) and, as a second candidate,
// its drift over the steady-state rows' recording order (kPsiDrift beside
// the mean). The mean is a motor property the diagnosed calibration keeps;
// the drift is the test's and goes.
#include <cmath>

#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm MagnetTemperatureTerm() {
  EffectTerm t;
  t.effect = "magnet_temperature";
  t.candidates = {{"magnet_temperature", kPsi}, {"magnet_temperature", kPsiDrift, 0, kPsi}};
  // The magnet flux shows in the steady-state rows' back-EMF and torque
  // only; a drift needs a few of them.
  t.testable = [](const Candidate& c, const Model& m) {
    return !m.ss.empty() && (c.block != kPsiDrift || m.ss.size() >= 3);
  };
  t.describe = [](const Candidate& c, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    // The mean over the steady-state rows; a drift (docs/diagnosis-report.md)
    // also as psi_pm at the first and the last row in recording order.
    SetParam(out, "psi_pm_wb", m.PsiPm(p), m.psi_nom * kScalePsi * Sd(f, kPsi, 0));
    if (c.block == kPsiDrift) {
      out->parameters["psi_pm_start_wb"] = m.PsiPm(p, 0.0);
      out->parameters["psi_pm_end_wb"] = m.PsiPm(p, 1.0);
      const double sm = kScalePsi * Sd(f, kPsi, 0), sdr = 0.5 * kScalePsi * Sd(f, kPsiDrift, 0);
      out->parameter_std["psi_pm_start_wb"] = m.psi_nom * std::hypot(sm, sdr);
      out->parameter_std["psi_pm_end_wb"] = m.psi_nom * std::hypot(sm, sdr);
    }
  };
  t.artefact_blocks = {kPsiDrift};
  return t;
}

}  // namespace fluxcal::diag::detail
