// A simulated EOL run with the digital twin (`fluxcal simulate`): the twin's
// motor, effects and test plan set up step by step (each step as the
// command line states it, so a caller reports each error where it comes
// from), then simulated into a recording set and its truth document
// (simulation/twin.h). The twin's own types stay behind this header.
#ifndef FLUXCAL_PIPELINE_SIMULATE_H_
#define FLUXCAL_PIPELINE_SIMULATE_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {

class SimulationSetup {
 public:
  // The built-in twin motor and plan, seed 1, the twin's default serial.
  SimulationSetup();
  ~SimulationSetup();
  SimulationSetup(SimulationSetup&&) noexcept;
  SimulationSetup& operator=(SimulationSetup&&) noexcept;

  absl::Status LoadMotorJson(const std::string& path);   // the motor (and what else the file states)
  void set_seed(uint64_t seed);
  uint64_t seed() const;
  void set_serial(const std::string& serial);
  const std::string& serial() const;
  // The motor perturbed as production spread, reproducible from the seed.
  void SpreadAsProduction();
  // Non-ideal effects "k=v,..." and noise_a=A (simulation/effects.h).
  absl::Status SetEffects(const std::string& spec);
  absl::Status LoadPlanJson(const std::string& path);
  // Every third locked point repeated at this DC-link voltage.
  void RepeatAtSecondUdc(double udc_v);

  size_t points() const;
  size_t steady_state_rows() const;
  std::vector<std::string> ActiveEffects() const;

 private:
  friend struct SimulationAccess;
  struct State;
  std::unique_ptr<State> state_;
};

struct SimulationOutput {
  io::RecordingSet set;
  std::string truth_json;   // DIR.truth.json: true inductances and effect parameters
  bool clipped = false;     // the modulator clipped in some points
};
absl::StatusOr<SimulationOutput> Simulate(const SimulationSetup& setup);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_SIMULATE_H_
