// fluxcal validate <recording-set> [--json]
// Reads and strictly validates a recording set (recording-format.md) without
// identifying anything: what an EOL station runs before uploading. On
// success prints what the set holds; on failure exits 1 with the reader's
// message (file, line and field) on stderr and, with --json, as
// {"valid": false, "error": ...} on stdout.
#include <algorithm>
#include <cstdio>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
namespace {

const FlagSpecs kValidateFlags = {
    JsonFlag("the validation result"),
};

int RunValidate(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kValidateFlags);
  if (!args.ok() || args->positional.size() != 1) {
    std::fprintf(stderr, "fluxcal validate: usage: fluxcal validate <recording-set> [--json]\n");
    return 2;
  }
  const bool json = args->Has("json");
  auto set = io::ReadRecordingSet(args->positional[0]);
  if (!set.ok()) {
    std::fprintf(stderr, "fluxcal validate: %s\n", std::string(set.status().message()).c_str());
    if (json) {
      PrintJson({{"valid", false}, {"error", std::string(set.status().message())}});
    }
    return 1;
  }
  const auto& m = set->manifest;
  size_t samples = 0, rotating = 0, min_samples = SIZE_MAX;
  for (size_t k = 0; k < set->waveforms.size(); ++k) {
    samples += set->waveforms[k].size();
    min_samples = std::min(min_samples, set->waveforms[k].size());
    rotating += m.points[k].speed_rpm != 0.0;
  }
  if (set->waveforms.empty()) min_samples = 0;
  const double fs = m.drive.f_sample_hz;
  const double f_inj = m.injection ? m.injection->frequency_hz : 0.0;
  nlohmann::json j = {{"valid", true},
                      {"serial", m.serial},
                      {"format", m.format},
                      {"points", m.points.size()},
                      {"rotating_points", rotating},
                      {"samples", samples},
                      {"shortest_point_injection_periods", f_inj > 0 ? min_samples * f_inj / fs : 0.0},
                      {"f_sample_hz", fs},
                      {"injection_hz", f_inj},
                      {"steady_state_rows", set->steady_state.size()},
                      {"hf_results_rows", set->hf_results.size()}};
  if (json) {
    PrintJson(j);
  } else {
    std::printf("%s: valid %s set, serial %s: %zu points (%zu rotating), %zu samples at %g Hz, "
                "injection %g Hz, %zu steady-state rows, %zu hf_results rows\n",
                args->positional[0].c_str(), m.format.c_str(), m.serial.c_str(), m.points.size(), rotating,
                samples, fs, f_inj, set->steady_state.size(), set->hf_results.size());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("validate", "strictly validate a recording set (file, line and field on error)",
                         RunValidate,
                         "fluxcal validate <recording-set> [--json]",
                         kValidateFlags);

}  // namespace fluxcal::cli
