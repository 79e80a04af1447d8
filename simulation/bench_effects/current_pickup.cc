// Interference picked up by one current sensor's wiring (mains at 50 Hz, a
// neighbouring drive): phase a reads a sin(2 pi f t + phase) more than
// flows. At one frequency at every operating point, and in the zero
// sequence (ia + ib + ic), which a star winding's currents cannot carry.
#include <cmath>
#include <numbers>

#include "simulation/bench_effects/simple.h"

namespace fluxcal::sim {
namespace {

class CurrentPickup : public SimpleBenchEffect {
 public:
  CurrentPickup()
      : SimpleBenchEffect({{"pickup_a", "A", 0.0, "amplitude of the interference on phase a's sensor"},
                           {"pickup_hz", "Hz", 50.0, "its frequency"},
                           {"pickup_phase_rad", "rad", 0.0, "its phase at each test's start"}},
                          1) {}
  std::string_view Name() const override { return "current_sensor_interference"; }
  std::string_view Meaning() const override { return "a current sensor picks up a line at a fixed frequency"; }
  void Sense(double t_s, double* ia, double*, double*) const override {
    *ia += Value(0) * std::sin(2 * std::numbers::pi * Value(1) * t_s + Value(2));
  }
};

}  // namespace

std::unique_ptr<BenchEffect> MakeCurrentPickup() { return std::make_unique<CurrentPickup>(); }

}  // namespace fluxcal::sim
