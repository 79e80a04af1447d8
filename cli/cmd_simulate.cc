// fluxcal simulate [--motor motor.json] [--plan plan.json] [--effects k=v,...]
//                  [--seed N] [--serial S] [--spread] --out DIR [--force] [--json]
// Writes a recording set (docs/recording-format.md) and, beside it (never
// inside), DIR.truth.json with the true inductances and effect parameters.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "absl/strings/numbers.h"
#include "absl/strings/str_join.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "pipeline/simulate.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& msg, int code = 1) { return CommandError("simulate", msg, code); }

const FlagSpecs kSimulateFlags = {
    {"out", "DIR", "recording set directory to write (required)"},
    {"motor", "FILE", "motor JSON (default the built-in twin motor)"},
    {"plan", "FILE", "test plan JSON: operating points, steady-state rows (default the built-in plan)"},
    {"effects", "K=V,...", "non-ideal effects and noise_a=A (current noise, A per phase; default 0.05)"},
    {"second-udc-v", "V", "repeat every third locked point at this DC-link voltage, V (separates dead time from "
                          "the switches' threshold voltage)"},
    {"seed", "N", "random seed, integer (default 1)"},
    {"serial", "S", "motor serial written to the manifest"},
    {"spread", "", "perturb the motor as production spread (from --seed)"},
    {"noise-a", "A", "accepted for compatibility; has no effect (use --effects noise_a=A)"},
    kJsonFlag,
    kForceFlag,
};

int RunSimulate(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kSimulateFlags);
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  auto out = args->Get("out");
  if (!out || !args->positional.empty()) {
    return Fail("usage: fluxcal simulate [--motor motor.json] [--plan plan.json] "
                "[--effects k=v,...] [--second-udc-v V] [--seed N] [--serial S] [--spread] --out DIR [--force] [--json]", 2);
  }
  pipeline::SimulationSetup setup;
  if (auto m = args->Get("motor")) {
    if (auto st = setup.LoadMotorJson(*m); !st.ok()) return Fail(std::string(st.message()));
  }
  if (auto s = args->Get("seed")) {
    uint64_t seed = 0;
    if (!absl::SimpleAtoi(*s, &seed)) return Fail("flag --seed: expected an integer, got '" + *s + "'", 2);
    setup.set_seed(seed);
  }
  if (auto s = args->Get("serial")) setup.set_serial(*s);
  if (args->Has("spread")) setup.SpreadAsProduction();
  if (auto e = args->Get("effects")) {
    if (auto st = setup.SetEffects(*e); !st.ok()) return Fail(std::string(st.message()), 2);
  }
  if (auto p = args->Get("plan")) {
    if (auto st = setup.LoadPlanJson(*p); !st.ok()) return Fail(std::string(st.message()));
  }
  auto second_udc = args->GetDouble("second-udc-v");
  if (!second_udc.ok()) return Fail(std::string(second_udc.status().message()), 2);
  if (second_udc->has_value()) {
    if (!(**second_udc > 0)) return Fail("flag --second-udc-v: must be positive", 2);
    setup.RepeatAtSecondUdc(**second_udc);
  }
  // Every flag checked: the overwrite rule (cli/args.h), before the
  // simulation: a directory with files in it, or DIR.truth.json, is
  // refused unless --force.
  std::string dir = *out;
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  const std::string truth = dir + ".truth.json";
  if (auto e = CheckOverwrite(*args, {{"out", dir}, {"out", truth}}); !e.empty()) return Fail(e);
  const auto t0 = std::chrono::steady_clock::now();
  std::fprintf(stderr, "simulate: %zu points, %zu steady-state rows, effects: %s\n", setup.points(),
               setup.steady_state_rows(), absl::StrJoin(setup.ActiveEffects(), ",").c_str());
  auto res = pipeline::Simulate(setup);
  if (!res.ok()) return Fail(std::string(res.status().message()));
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (auto st = io::WriteRecordingSet(dir, res->set); !st.ok()) return Fail(std::string(st.message()));
  if (auto st = io::WriteFileAtomically(truth, res->truth_json); !st.ok()) {
    return Fail(std::string(st.message()));
  }
  if (res->clipped) std::fprintf(stderr, "simulate: warning: the modulator clipped in some points\n");
  std::fprintf(stderr, "simulate: wrote %s and %s in %.2f s\n", dir.c_str(), truth.c_str(), secs);
  if (args->Has("json")) {
    nlohmann::json j = {{"set", dir}, {"truth", truth}, {"serial", setup.serial()},
                        {"points", setup.points()}, {"steady_state_rows", setup.steady_state_rows()},
                        {"effects", setup.ActiveEffects()}, {"seconds", secs},
                        {"clipped", res->clipped}};
    PrintJson(j);
  } else {
    std::cout << dir << "\n" << truth << "\n";
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("simulate", "simulate an EOL run with the digital twin, write a recording set",
                         RunSimulate,
                         "fluxcal simulate [--motor motor.json] [--plan plan.json] [--effects k=v,...] [--second-udc-v V] [--seed N] [--serial S] [--spread] --out DIR [--force] [--json]",
                         kSimulateFlags);

}  // namespace fluxcal::cli
