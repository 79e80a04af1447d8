// An angle sensor mounted off the shaft's axis (or a resolver with a
// once-per-revolution error): the reading is off by a sin(th_m + phase),
// once per mechanical revolution -- electrically a / pole pairs ... times
// pole pairs: the error is a in electrical radians. The catalogue's
// position_sensor_harmonic is the twice-per-electrical-period error of
// unequal sine/cosine windings; this one follows the mechanical angle.
#include <cmath>

#include "simulation/bench_effects/simple.h"

namespace fluxcal::sim {
namespace {

class EncoderEccentricity : public SimpleBenchEffect {
 public:
  EncoderEccentricity()
      : SimpleBenchEffect({{"encoder_eccentricity_rad", "rad", 0.0, "angle error amplitude, electrical radians"},
                           {"encoder_eccentricity_phase_rad", "rad", 0.0, "its mechanical phase"}},
                          1) {}
  std::string_view Name() const override { return "angle_sensor_eccentricity"; }
  std::string_view Meaning() const override {
    return "the angle sensor's error follows the mechanical angle (off-axis mounting)";
  }
  double AngleError(double /*th_e*/, double th_m) const override { return Value(0) * std::sin(th_m + Value(1)); }
};

}  // namespace

std::unique_ptr<BenchEffect> MakeEncoderEccentricity() { return std::make_unique<EncoderEccentricity>(); }

}  // namespace fluxcal::sim
