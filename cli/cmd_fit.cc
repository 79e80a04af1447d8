// fluxcal fit <recording-set | hf_results.csv> [--model auto|analytic|spline|splineR|poly|polyN]
//             --out calibration.json [--svg PLOT.svg] [--json] [--serial S --pole-pairs P]
// Identifies every waveform point (least squares), then fits the
// flux-linkage surfaces jointly with hf_results and steady-state rows.
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "absl/strings/numbers.h"
#include "cli/args.h"
#include "cli/command.h"
#include "fitting/fit.h"
#include "fitting/plot.h"
#include "io/csv.h"
#include "identification/identify.h"
#include "pipeline/points.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) {
  std::fprintf(stderr, "fluxcal fit: %s\n", m.c_str());
  return code;
}

int RunFit(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, {"model", "out", "serial", "pole-pairs", "svg"}, {"json"});
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  if (args->positional.size() != 1 || !args->Get("out")) {
    return Fail("usage: fluxcal fit <recording-set | hf_results.csv> [--model auto|analytic|spline|splineR|poly|polyN] "
                "--out calibration.json [--svg PLOT.svg] [--json]", 2);
  }
  const std::string input = args->positional[0];
  fit::FitData data;
  if (std::filesystem::is_directory(input)) {
    auto set = io::ReadRecordingSet(input);
    if (!set.ok()) return Fail(std::string(set.status().message()));
    ident::IdentifyOptions opt;
    opt.progress = [](size_t k, size_t n) {
      std::fprintf(stderr, "\rfit: identifying point %zu/%zu", k + 1, n);
      if (k + 1 == n) std::fprintf(stderr, "\n");
    };
    auto d = pipeline::FitDataFromSet(*set, opt);
    if (!d.ok()) return Fail(std::string(d.status().message()));
    data = std::move(*d);
  } else {
    auto rows = io::ReadHfResultsCsv(input);
    if (!rows.ok()) return Fail(std::string(rows.status().message()));
    data = fit::FitDataFromHfRows(nullptr, *rows);
    data.serial = args->Get("serial").value_or("UNKNOWN");
    if (auto pp = args->Get("pole-pairs")) {
      if (!absl::SimpleAtoi(*pp, &data.pole_pairs) || data.pole_pairs < 1) {
        return Fail("flag --pole-pairs: expected a positive integer", 2);
      }
    }
  }
  fit::FitOptions fo;
  fo.model = args->Get("model").value_or("auto");
  std::fprintf(stderr, "fit: %zu inductance points, %zu steady-state rows, model %s\n",
               data.inductances.size(), data.steady_state.size(), fo.model.c_str());
  auto cal = fit::Fit(data, fo);
  if (!cal.ok()) return Fail(std::string(cal.status().message()));
  if (auto st = fit::SaveCalibrationFile(*args->Get("out"), *cal); !st.ok()) return Fail(std::string(st.message()));
  for (const auto& c : cal->summary.candidates) std::fprintf(stderr, "fit:   %s\n", c.c_str());
  for (const auto& e : cal->summary.excluded) std::fprintf(stderr, "fit: point %s\n", e.c_str());
  if (auto svg = args->Get("svg")) {
    if (auto st = io::WriteFileAtomically(*svg, fit::PlotFitSvg(*cal, data)); !st.ok()) {
      return Fail(std::string(st.message()));
    }
    std::fprintf(stderr, "fit: plot %s\n", svg->c_str());
  }
  if (args->Has("json")) {
    nlohmann::json j = cal->ToJson();
    j["out"] = *args->Get("out");
    std::cout << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  } else {
    std::printf("serial %s: model %s, %d observations, rms %.3f %%, psi_pm %.6g Wb -> %s\n",
                cal->serial().c_str(), cal->family().Name().c_str(), cal->summary.observations,
                100 * cal->summary.rms_relative, cal->psi_pm_wb(), args->Get("out")->c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("fit", "fit flux-linkage surfaces (Ceres) to a recording set or hf_results.csv",
                         RunFit);

}  // namespace fluxcal::cli
