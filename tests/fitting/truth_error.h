// A calibration against the twin's truth points (tests/fitting only).
#ifndef FLUXCAL_TESTS_FITTING_TRUTH_ERROR_H_
#define FLUXCAL_TESTS_FITTING_TRUTH_ERROR_H_

#include <algorithm>
#include <cmath>
#include <vector>

#include "fitting/calibration.h"
#include "simulation/twin.h"

namespace fluxcal::fit {

struct TruthError {
  double inductance_rms = 0;   // Ldd and Lqq together, relative RMS
  double flux_max = 0;         // worst |psi - truth| over max(|psi_truth|, psi_pm)
};

inline TruthError AgainstTruth(const Calibration& cal, const std::vector<sim::TruthPoint>& truth) {
  TruthError out;
  double e = 0;
  for (const auto& t : truth) {
    const auto p = cal.Predict(t.id_true_a, t.iq_true_a);
    e += std::pow(p.ldd_h / t.ldd_h - 1, 2) + std::pow(p.lqq_h / t.lqq_h - 1, 2);
    out.flux_max = std::max(out.flux_max, std::hypot(p.psi_d_wb - t.psi_d_wb, p.psi_q_wb - t.psi_q_wb) /
                                              std::max(std::hypot(t.psi_d_wb, t.psi_q_wb), t.psi_pm_wb));
  }
  out.inductance_rms = std::sqrt(e / (2 * truth.size()));
  return out;
}

}  // namespace fluxcal::fit

#endif  // FLUXCAL_TESTS_FITTING_TRUTH_ERROR_H_
