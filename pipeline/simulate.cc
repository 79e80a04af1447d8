#include "pipeline/simulate.h"

#include <utility>

#include "simulation/effects.h"
#include "simulation/twin.h"

namespace fluxcal::pipeline {

struct SimulationSetup::State {
  sim::TwinConfig cfg;
  sim::Plan plan = sim::DefaultPlan();
};

struct SimulationAccess {
  static const SimulationSetup::State& Of(const SimulationSetup& s) { return *s.state_; }
};

SimulationSetup::SimulationSetup() : state_(std::make_unique<State>()) {}
SimulationSetup::~SimulationSetup() = default;
SimulationSetup::SimulationSetup(SimulationSetup&&) noexcept = default;
SimulationSetup& SimulationSetup::operator=(SimulationSetup&&) noexcept = default;

absl::Status SimulationSetup::LoadMotorJson(const std::string& path) { return sim::LoadMotorJson(path, &state_->cfg); }
void SimulationSetup::set_seed(uint64_t seed) { state_->cfg.seed = seed; }
uint64_t SimulationSetup::seed() const { return state_->cfg.seed; }
void SimulationSetup::set_serial(const std::string& serial) { state_->cfg.serial = serial; }
const std::string& SimulationSetup::serial() const { return state_->cfg.serial; }
void SimulationSetup::SpreadAsProduction() {
  state_->cfg.motor = sim::PerturbForProduction(state_->cfg.motor, state_->cfg.seed);
}
absl::Status SimulationSetup::SetEffects(const std::string& spec) {
  double noise = state_->cfg.sensors.noise_a;
  if (auto st = sim::ParseEffects(spec, &state_->cfg.effects, &noise); !st.ok()) return st;
  state_->cfg.sensors.noise_a = noise;
  return absl::OkStatus();
}
absl::Status SimulationSetup::LoadPlanJson(const std::string& path) {
  auto plan = sim::LoadPlanJson(path);
  if (!plan.ok()) return plan.status();
  state_->plan = std::move(*plan);
  return absl::OkStatus();
}
void SimulationSetup::RepeatAtSecondUdc(double udc_v) {
  state_->plan = sim::WithSecondUdc(std::move(state_->plan), udc_v);
}
size_t SimulationSetup::points() const { return state_->plan.points.size(); }
size_t SimulationSetup::steady_state_rows() const { return state_->plan.steady_state.size(); }
std::vector<std::string> SimulationSetup::ActiveEffects() const { return sim::ActiveEffectNames(state_->cfg.effects); }

absl::StatusOr<SimulationOutput> Simulate(const SimulationSetup& setup) {
  const auto& s = SimulationAccess::Of(setup);
  auto res = sim::Simulate(s.cfg, s.plan);
  if (!res.ok()) return res.status();
  SimulationOutput out;
  out.truth_json = sim::TruthJson(s.cfg, *res);
  out.clipped = res->clipped;
  out.set = std::move(res->set);
  return out;
}

}  // namespace fluxcal::pipeline
