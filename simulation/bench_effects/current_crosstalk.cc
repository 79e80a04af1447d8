// Crosstalk between current sensors: phase b's sensor also sees a fraction
// c of phase a's current (a busbar's field reaching the neighbouring
// sensor): ib_meas = ib + c ia. Unlike unequal gains (the catalogue's
// current_sensor_gain, diagonal) it couples two phases, and what it adds
// shows in the zero sequence (ia + ib + ic) as c ia.
#include "simulation/bench_effects/simple.h"

namespace fluxcal::sim {
namespace {

class CurrentCrosstalk : public SimpleBenchEffect {
 public:
  CurrentCrosstalk()
      : SimpleBenchEffect({{"crosstalk_ab", "1", 0.0, "share of phase a's current phase b's sensor reads"}}, 1) {}
  std::string_view Name() const override { return "current_sensor_crosstalk"; }
  std::string_view Meaning() const override { return "one current sensor reads part of another phase's current"; }
  void Sense(double, double* ia, double* ib, double*) const override { *ib += Value(0) * *ia; }
};

}  // namespace

std::unique_ptr<BenchEffect> MakeCurrentCrosstalk() { return std::make_unique<CurrentCrosstalk>(); }

}  // namespace fluxcal::sim
