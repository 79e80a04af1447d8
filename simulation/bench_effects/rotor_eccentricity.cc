// Rotor eccentricity: a rotor off the stator's centre narrows the air gap on
// one side, once per mechanical revolution, and the current-dependent flux
// with it: psi = psi_pm + (psi(i) - psi_pm)(1 + e cos(th_m - phase)), the
// inductance scaled alike (first order in the relative eccentricity e; a
// static eccentricity of a few percent of the air gap is a common
// assembly defect). At speed: the HF response and the fundamental carry
// sidebands at the mechanical frequency; at standstill: locked points at one
// electrical angle in different pole-pair sectors differ.
#include <cmath>

#include "simulation/bench_effects/simple.h"

namespace fluxcal::sim {
namespace {

class RotorEccentricity : public SimpleBenchEffect {
 public:
  RotorEccentricity()
      : SimpleBenchEffect({{"eccentricity", "1", 0.0, "relative change of the current-dependent flux, once per revolution"},
                           {"eccentricity_phase_rad", "rad", 0.0, "mechanical angle of the narrowest air gap"}},
                          1) {}
  std::string_view Name() const override { return "rotor_eccentricity"; }
  std::string_view Meaning() const override {
    return "an eccentric rotor: the current-dependent flux varies once per mechanical revolution";
  }
  void ModifyMagnetics(double /*th_e*/, double th_m, double psi_pm_wb, double* psi_d, double* psi_q, double* ldd,
                       double* lqq, double* ldq) const override {
    const double f = 1.0 + Value(0) * std::cos(th_m - Value(1));
    *psi_d = psi_pm_wb + (*psi_d - psi_pm_wb) * f;
    *psi_q *= f;
    if (ldd != nullptr) {
      *ldd *= f;
      *lqq *= f;
      *ldq *= f;
    }
  }
};

}  // namespace

std::unique_ptr<BenchEffect> MakeRotorEccentricity() { return std::make_unique<RotorEccentricity>(); }

}  // namespace fluxcal::sim
