// fluxcal fit <recording-set> [--model auto|analytic|spline|splineR|poly|polyN]
//             --out calibration.json [--svg PLOT.svg] [--json] [machine-fact flags]
// fluxcal fit hf_results.csv --serial S --pole-pairs P --psi-pm-wb WB [--rs-ohm R] [--udc-v V] ...
// fluxcal fit --map map.csv --pole-pairs P [--psi-std-wb S] [--rs-ohm R] [--udc-v V] [--serial S]
//             [--magnet-temp-coeff-per-k A] [--magnet-reference-c C] [--convention C] [--current S] [--flux-amplitude S] [--units U] --out calibration.json
// Machine facts (serial, pole pairs, psi_pm, Rs, Udc, the magnet
// temperature coefficient and reference) come from the set's
// manifest or these flags, never from a default (pipeline/facts.h).
// Identifies every waveform point (least squares), then fits the
// flux-linkage surfaces jointly with hf_results and steady-state rows; or
// fits them to a flux map's nodes (io/flux_map.h, pipeline/local_fit.h),
// read in the convention the flags name (cli/support_flux_map.h) and
// refused when implausible; the fit's summary reports its flux error over
// the nodes (FitSummary::flux_*).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_flux_map.h"
#include "cli/support_progress.h"
#include "io/csv.h"
#include "io/flux_map.h"
#include "io/plausibility.h"
#include "pipeline/facts.h"
#include "pipeline/local_fit.h"
#include "pipeline/points.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("fit", m, code); }

const FlagSpecs kFitFlags = [] {
  FlagSpecs f = {
    OutFlag("calibration JSON"),
    {"model", "M", "auto|analytic|poly|polyN (N 2..10)|spline|splineN (N 1..8)|smooth|smooth-asym (default auto: best by BIC)"},
    {"svg", "FILE", "also plot the fit against the identified inductances (SVG; not with --map)"},
    {"map", "CSV", "fit a flux map psi(id, iq) instead of a recording set (no positional argument)"},
    {"pole-pairs", "P", "pole pairs, integer 1..100 (required for hf_results.csv and --map: they do not say)"},
    {"serial", "S", "motor serial (required for hf_results.csv; --map: default the map file's name)"},
    {"psi-pm-wb", "WB", "nominal magnet flux, Wb (required for hf_results.csv: not observable from inductances)"},
    {"rs-ohm", "R", "nominal stator resistance, ohm (optional; unknown if no one states it)"},
    {"udc-v", "V", "DC-link voltage of the drive, V (optional; fw/mtpv exports need it)"},
    {"magnet-temp-coeff-per-k", "A", "relative change of psi_pm per kelvin of magnet temperature, 1/K (NdFeB about "
                                     "-0.0011; optional: tables at another magnet temperature need it)"},
    {"magnet-reference-c", "C", "magnet temperature the data were taken at, degC, for data that record none "
                                "(a flux map; refused when they record temperature_c)"},
    {"psi-std-wb", "S", "with --map: flux standard deviation per component, Wb (default 0.2 % of the largest |psi|)"},
    JsonFlag("the calibration and fit summary"),
    kForceFlag,
  };
  for (auto c : FluxMapConventionFlags()) {
    c.help = "with --map: " + c.help;
    f.push_back(c);
  }
  return f;
}();

int RunFit(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kFitFlags);
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  if (auto e = CheckOutToStdout(*args); !e.empty()) return Fail(e, 2);
  // The fit's own parser, before any identification: a typo costs nothing.
  if (auto m = args->Get("model")) {
    if (auto parsed = pipeline::CheckModelName(*m); !parsed.ok()) return Fail(std::string(parsed.message()), 2);
  }
  if (int pp = 0; args->Get("pole-pairs") && (!absl::SimpleAtoi(*args->Get("pole-pairs"), &pp) || pp < 1)) {
    return Fail("flag --pole-pairs: expected a positive integer", 2);
  }
  const bool from_map = args->Get("map").has_value();
  if (args->positional.size() != (from_map ? 0u : 1u) || !args->Get("out")) {
    return Fail("usage: fluxcal fit <recording-set> [--model M] --out calibration.json [--svg PLOT.svg] [--json]\n"
                "       fluxcal fit hf_results.csv --serial S --pole-pairs P --psi-pm-wb WB [--rs-ohm R] [--udc-v V] "
                "[--model M] --out calibration.json [--json]\n"
                "       fluxcal fit --map map.csv --pole-pairs P [--psi-std-wb S] [--rs-ohm R] [--udc-v V] [--serial S] "
                "[--convention C] [--current S] [--flux-amplitude S] [--units U] [--model M] --out calibration.json "
                "[--json]", 2);
  }
  if (!from_map && args->Get("psi-std-wb")) return Fail("flag --psi-std-wb needs --map", 2);
  // The machine facts the flags state (pipeline/facts.h merges them).
  pipeline::StatedFacts stated;
  if (auto v = args->Get("serial")) stated.serial = *v;
  if (auto v = args->Get("pole-pairs")) {
    int pp = 0;
    if (!absl::SimpleAtoi(*v, &pp)) return Fail("flag --pole-pairs: expected an integer 1..100", 2);
    stated.pole_pairs = pp;
  }
  for (auto [flag, dst] : {std::pair<const char*, std::optional<double>*>{"psi-pm-wb", &stated.psi_pm_wb},
                           {"rs-ohm", &stated.rs_ohm}, {"udc-v", &stated.udc_v},
                           {"magnet-temp-coeff-per-k", &stated.psi_pm_temp_coeff_per_k},
                           {"magnet-reference-c", &stated.magnet_reference_c}}) {
    auto v = args->GetDouble(flag);
    if (!v.ok()) return Fail(std::string(v.status().message()), 2);
    *dst = *v;
  }
  pipeline::FactSource source = pipeline::FactSource::kRecordingSet;
  if (!from_map && HasFluxMapConventionFlag(*args)) {
    return Fail("flags --convention, --current, --flux-amplitude and --units describe a flux map: they need --map", 2);
  }
  auto convention = FluxMapConventionFromArgs(*args);
  if (!convention.ok()) return Fail(std::string(convention.status().message()), 2);
  if (from_map && args->Get("svg")) {
    // The plot draws the fit against identified inductances; a map has none.
    return Fail("--svg plots identified inductances, which a flux map does not have; check a map fit with "
                "`fluxcal compare`", 2);
  }
  const std::string input = from_map ? *args->Get("map") : args->positional[0];
  // A map's flags (it states no pole pairs, no serial).
  int pole_pairs = 0;
  absl::StatusOr<std::optional<double>> std_wb = std::optional<double>();
  std::string serial;
  if (from_map) {
    auto pp = args->Get("pole-pairs");
    if (!pp || !absl::SimpleAtoi(*pp, &pole_pairs) || !io::CheckPolePairs("pole_pairs", pole_pairs).ok()) {
      return Fail(absl::StrCat("--map needs --pole-pairs P (an integer 1..", io::kMaxPolePairs,
                               "): a flux map does not say"), 2);
    }
    std_wb = args->GetDouble("psi-std-wb");
    if (!std_wb.ok()) return Fail(std::string(std_wb.status().message()), 2);
    if (std_wb->has_value() && !(**std_wb > 0)) return Fail("flag --psi-std-wb: must be positive", 2);
    serial = args->Get("serial").value_or(std::filesystem::path(input).stem().string());
    if (!io::IsValidSerial(serial)) {
      return Fail("serial '" + io::Printable(serial) + "' (from " + (args->Get("serial") ? "--serial" : "the file name") +
                      ") is not 1 to 64 characters of A-Z a-z 0-9 - _ .; give --serial", 2);
    }
  }
  // Every flag checked: existing outputs are refused before any work (the
  // overwrite rule, cli/args.h).
  const OutputPath out_path{"out", *args->Get("out")}, svg_path{"svg", args->Get("svg").value_or("")};
  if (auto e = CheckOverwrite(*args, {out_path, svg_path}); !e.empty()) return Fail(e);
  fit::FitData data;
  std::optional<io::FluxMap> map;
  if (from_map) {
    io::FluxMapReadOptions ro;
    ro.convention = *convention;
    auto m = io::ReadFluxMapCsv(input, ro);
    if (!m.ok()) return Fail(std::string(m.status().message()));
    std::fprintf(stderr, "fit: map %s: %s\n", input.c_str(), m->convention.Describe().c_str());
    data = pipeline::FitDataFromFluxMap(*m, pole_pairs, std_wb->value_or(0.0), serial);
    source = pipeline::FactSource::kFluxMap;   // Rs and Udc: the flags', below
    std::fprintf(stderr, "fit: map %s, %zu x %zu nodes, sigma %.3g Wb per component%s\n", input.c_str(),
                 m->id_a.size(), m->iq_a.size(), data.fluxes.front().psi_std_wb,
                 data.psi_pm_prior_wb ? ", psi_pm prior from the node at (0, 0)" : "");
    map = std::move(*m);
  } else if (std::filesystem::is_directory(input)) {
    auto set = io::ReadRecordingSet(input);
    if (!set.ok()) return Fail(std::string(set.status().message()));
    // The facts before the (slow) identification: a conflict or a missing
    // fact costs nothing. Identified points do not change them.
    if (auto st = pipeline::CheckSetFacts(*set, stated); !st.ok()) return Fail(std::string(st.message()), 2);
    ident::IdentifyOptions opt;
    opt.progress = ProgressLine("fit: identifying point").Callback();
    auto d = pipeline::FitDataFromSet(*set, opt);
    if (!d.ok()) return Fail(std::string(d.status().message()));
    data = std::move(*d);
  } else {
    auto rows = io::ReadHfResultsCsv(input);
    if (!rows.ok()) return Fail(std::string(rows.status().message()));
    data = pipeline::FitDataFromHfResults(*rows);
    source = pipeline::FactSource::kHfResults;
  }
  std::vector<std::string> notes;
  if (auto st = pipeline::ApplyStatedFacts(stated, source, &data, &notes); !st.ok()) {
    return Fail(std::string(st.message()), 2);
  }
  for (const auto& n : notes) std::fprintf(stderr, "fit: %s\n", n.c_str());
  const std::string model = args->Get("model").value_or("auto");
  std::fprintf(stderr, "fit: %zu inductance points, %zu steady-state rows, %zu flux nodes, model %s\n",
               data.inductances.size(), data.steady_state.size(), data.fluxes.size(), model.c_str());
  auto cal = pipeline::FitCalibration(data, model);
  if (!cal.ok()) return Fail(std::string(cal.status().message()));
  const bool to_stdout = *args->Get("out") == "-";
  if (auto st = WriteNewOutput(*args, out_path, cal->ToJson().dump(2) + "\n"); !st.ok()) {
    return Fail(std::string(st.message()));
  }
  for (const auto& c : cal->summary.candidates) std::fprintf(stderr, "fit:   %s\n", c.c_str());
  for (const auto& e : cal->summary.excluded) std::fprintf(stderr, "fit: %s\n", e.c_str());
  std::fprintf(stderr, "fit: magnet temperature: %s\n", cal->MagnetTemperatureText().c_str());
  if (auto svg = args->Get("svg")) {
    if (auto st = WriteNewOutput(*args, svg_path, pipeline::FitPlotSvg(*cal, data)); !st.ok()) {
      return Fail(std::string(st.message()));
    }
    std::fprintf(stderr, "fit: plot %s\n", svg->c_str());
  }
  // A map fit's figure is its flux error over the map's nodes (the fit's
  // summary, FitSummary::flux_*); rms_relative covers inductances.
  const auto& sum = cal->summary;
  if (args->Has("json")) {
    nlohmann::json j = cal->ToJson();
    j["out"] = *args->Get("out");
    if (map) {
      j["map"] = {{"path", input},
                  {"nodes", sum.flux_nodes},
                  {"rms_relative", sum.flux_rms_relative},
                  {"max_relative", sum.flux_max_relative},
                  {"rms_wb", sum.flux_rms_wb},
                  {"max_wb", sum.flux_max_wb},
                  {"psi_scale_wb", sum.flux_scale_wb},
                  {"convention", FluxMapConventionJson(map->convention)}};
    }
    PrintJson(j);
  } else if (map) {
    std::fprintf(to_stdout ? stderr : stdout, "serial %s: model %s, %d observations, flux error against the map's %d nodes "
                "RMS %.3f %% max %.3f %% (of %.4g Wb), psi_pm %.6g Wb -> %s\n",
                cal->serial().c_str(), cal->family().Name().c_str(), sum.observations, sum.flux_nodes,
                100 * sum.flux_rms_relative, 100 * sum.flux_max_relative, sum.flux_scale_wb, cal->psi_pm_wb(),
                args->Get("out")->c_str());
  } else {
    std::fprintf(to_stdout ? stderr : stdout, "serial %s: model %s, %d observations, rms %.3f %%, psi_pm %.6g Wb -> %s\n",
                cal->serial().c_str(), cal->family().Name().c_str(), sum.observations,
                100 * sum.rms_relative, cal->psi_pm_wb(), args->Get("out")->c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("fit", "fit flux-linkage surfaces (Ceres) to a recording set or hf_results.csv",
                         RunFit,
                         "fluxcal fit <recording-set> --out calibration.json [--force] [--model M] [--svg PLOT.svg] [--udc-v V] [--rs-ohm R] [--json]\n"
                         "fluxcal fit hf_results.csv --serial S --pole-pairs P --psi-pm-wb WB [--rs-ohm R] [--udc-v V] --out calibration.json [--force] [--json]\n"
                         "fluxcal fit --map map.csv --pole-pairs P [--psi-std-wb S] [--rs-ohm R] [--udc-v V] [--serial S] [--convention C] "
                         "[--current S] [--flux-amplitude S] [--units U] [--model M] --out calibration.json [--json]",
                         kFitFlags);

}  // namespace fluxcal::cli
