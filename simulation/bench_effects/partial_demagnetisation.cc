// Partial demagnetisation: one magnet (or one pole's magnets) weaker than
// the others, after an overheating or an overcurrent, or a magnet chipped
// or missing at assembly. The magnet flux the winding links then varies
// with the mechanical angle; to first order (a weak pole's share of the
// linked flux is a smooth function of where it stands)
//   psi_d += -d psi_pm cos(th_m + phase),
// a modulation once per mechanical revolution whose back-EMF puts the
// classic fault sidebands f_e (1 +- 1/p) into the phase currents at speed
// (e.g. Rosero, Cusido, Garcia, Ortega, Romeral, "Study on the permanent
// magnet demagnetization fault in PMSMs", IEEE IECON 2006: sidebands at
// f_s (1 +- k/p)). At standstill it is a constant flux per point and
// invisible; its mean over a revolution is zero here (a uniform weakening
// is the catalogue's magnet_temperature). The catalogue has no model of it:
// the diagnosis must locate its mechanical-order lines and not explain them.
#include <cmath>

#include "simulation/bench_effects/simple.h"

namespace fluxcal::sim {
namespace {

class PartialDemagnetisation : public SimpleBenchEffect {
 public:
  PartialDemagnetisation()
      : SimpleBenchEffect({{"demagnetised_share", "1", 0.0,
                            "amplitude of the magnet flux's once-per-revolution variation, relative to psi_pm"},
                           {"demagnetised_phase_rad", "rad", 0.0, "mechanical angle of the weak pole"}},
                          1) {}
  std::string_view Name() const override { return "partial_demagnetisation"; }
  std::string_view Meaning() const override {
    return "one magnet weaker than the others: the magnet flux varies once per mechanical revolution";
  }
  void ModifyMagnetics(double /*th_e*/, double th_m, double psi_pm_wb, double* psi_d, double* /*psi_q*/, double*,
                       double*, double*) const override {
    *psi_d -= Value(0) * psi_pm_wb * std::cos(th_m + Value(1));
  }
};

}  // namespace

std::unique_ptr<BenchEffect> MakePartialDemagnetisation() { return std::make_unique<PartialDemagnetisation>(); }

}  // namespace fluxcal::sim
