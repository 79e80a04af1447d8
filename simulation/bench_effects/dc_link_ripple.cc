// DC-link ripple the modulator does not see (a rectifier's 300 Hz from a
// 50 Hz three-phase mains, a filtered or slow Udc measurement): the applied
// voltage is the command times 1 + r sin(2 pi f t + phase), so every
// voltage the inverter applies -- the injection, the fundamental -- grows
// sidebands at +-f.
#include <cmath>
#include <numbers>

#include "simulation/bench_effects/simple.h"

namespace fluxcal::sim {
namespace {

class DcLinkRipple : public SimpleBenchEffect {
 public:
  DcLinkRipple()
      : SimpleBenchEffect({{"udc_ripple", "1", 0.0, "relative amplitude of the DC-link ripple"},
                           {"udc_ripple_hz", "Hz", 300.0, "its frequency"},
                           {"udc_ripple_phase_rad", "rad", 0.0, "its phase at each test's start"}},
                          1) {}
  std::string_view Name() const override { return "dc_link_ripple"; }
  std::string_view Meaning() const override {
    return "the DC-link voltage ripples and the modulator does not compensate it";
  }
  double UdcFactor(double t_s) const override {
    return 1.0 + Value(0) * std::sin(2 * std::numbers::pi * Value(1) * t_s + Value(2));
  }
};

}  // namespace

std::unique_ptr<BenchEffect> MakeDcLinkRipple() { return std::make_unique<DcLinkRipple>(); }

}  // namespace fluxcal::sim
