// fluxcal replay <recording-set> --calibration cal.json [--closed-loop]
//                [--bandwidth-hz F] [--ld-nominal-h L] [--lq-nominal-h L]
//                [--settle-s S] [--json]
// Replays every recorded test through the digital twin with a calibration
// as the motor's magnetics and reports, per point, the RMS difference between
// simulated and recorded phase currents: open loop (the recorded commands
// drive the plant; no assumption about the bench) or closed loop (the
// manifest's references through the twin's bench controller, whose gains a
// recording does not declare: the flags are the assumption). docs/simulation.md.
#include <cmath>
#include <cstdio>
#include <optional>
#include <utility>

#include "absl/strings/str_format.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "pipeline/pipeline.h"
#include "pipeline/replay.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("replay", m, code); }

const FlagSpecs kReplayFlags = {
    {"calibration", "FILE", "calibration JSON driving the twin (required)"},
    {"closed-loop", "", "the manifest's references through the twin's controller (default open loop: the recorded commands)"},
    {"bandwidth-hz", "F", "closed loop: current-controller bandwidth, Hz (default 80)"},
    {"ld-nominal-h", "L", "closed loop: controller's nominal Ld, H (default 0.18e-3)"},
    {"lq-nominal-h", "L", "closed loop: controller's nominal Lq, H (default 0.35e-3)"},
    {"settle-s", "S", "closed loop: settling time before recording, s (default 0.03)"},
    kJsonFlag,
};

int RunReplay(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kReplayFlags);
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  // Flag values checked before the set is read and replayed.
  for (const char* flag : {"bandwidth-hz", "ld-nominal-h", "lq-nominal-h", "settle-s"}) {
    auto v = args->GetDouble(flag);
    if (!v.ok()) return Fail(std::string(v.status().message()), 2);
    if (*v && !(**v > 0)) return Fail(absl::StrFormat("flag --%s: must be positive", flag), 2);
  }
  if (args->positional.size() != 1 || !args->Get("calibration")) {
    return Fail("usage: fluxcal replay <recording-set> --calibration cal.json [--closed-loop] "
                "[--bandwidth-hz F] [--ld-nominal-h L] [--lq-nominal-h L] [--settle-s S] [--json]", 2);
  }
  const bool closed = args->Has("closed-loop");
  auto set = io::ReadRecordingSet(args->positional[0]);
  if (!set.ok()) return Fail(std::string(set.status().message()));
  auto cal = pipeline::LoadCalibrationFile(*args->Get("calibration"));
  if (!cal.ok()) return Fail(std::string(cal.status().message()));
  std::fprintf(stderr, "replay: %zu points of %s through the twin (%s loop), calibration %s v%d\n",
               set->waveforms.size(), set->manifest.serial.c_str(), closed ? "closed" : "open",
               cal->family().Name().c_str(), cal->version);
  // The controller flags (checked positive above) and the replay itself
  // (pipeline/replay.h).
  pipeline::ReplayRequest request;
  request.closed_loop = closed;
  if (closed) {
    for (const auto& [flag, target] : {std::pair<const char*, std::optional<double>*>{"bandwidth-hz", &request.bandwidth_hz},
                                       {"ld-nominal-h", &request.ld_nominal_h},
                                       {"lq-nominal-h", &request.lq_nominal_h},
                                       {"settle-s", &request.settle_s}}) {
      auto v = args->GetDouble(flag);
      if (!v.ok()) return Fail(std::string(v.status().message()), 2);
      *target = *v;
    }
  }
  auto rep = pipeline::ReplayRecording(*set, *cal, request);
  if (!rep.ok()) return Fail(std::string(rep.status().message()));
  const double rs = rep->rs_ohm;
  nlohmann::json points = nlohmann::json::array();
  for (const auto& p : rep->points) {
    points.push_back({{"point", p.point}, {"id_ref_a", p.id_ref_a}, {"iq_ref_a", p.iq_ref_a},
                      {"speed_rpm", p.speed_rpm}, {"residual_rms_a", p.residual_rms_a}});
  }
  const double total = rep->residual_rms_a;
  if (args->Has("json")) {
    nlohmann::json j = {{"serial", set->manifest.serial},
                        {"mode", closed ? "closed_loop" : "open_loop"},
                        {"calibration_model", cal->family().Name()},
                        {"rs_ohm", rs},
                        {"residual_rms_a", total},
                        {"points", points}};
    if (closed) {
      j["controller"] = {{"bandwidth_hz", rep->bandwidth_hz}, {"ld_nominal_h", rep->ld_nominal_h},
                         {"lq_nominal_h", rep->lq_nominal_h}, {"settle_s", rep->settle_s}};
    }
    PrintJson(j);
    return 0;
  }
  std::printf("%-8s %9s %9s %9s %14s\n", "point", "id_ref_a", "iq_ref_a", "speed_rpm", "residual_rms_a");
  for (const auto& p : points) {
    std::printf("%-8s %9.1f %9.1f %9.0f %14.4f\n", p["point"].get<std::string>().c_str(), p["id_ref_a"].get<double>(),
                p["iq_ref_a"].get<double>(), p["speed_rpm"].get<double>(), p["residual_rms_a"].get<double>());
  }
  std::printf("all points: %.4f A RMS (%s loop)\n", total, closed ? "closed" : "open");
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("replay", "replay recorded tests through the twin with a calibration (open/closed loop)",
                         RunReplay,
                         "fluxcal replay <recording-set> --calibration cal.json [--closed-loop] [--bandwidth-hz F] [--ld-nominal-h L] [--lq-nominal-h L] [--settle-s S] [--json]",
                         kReplayFlags);

}  // namespace fluxcal::cli
