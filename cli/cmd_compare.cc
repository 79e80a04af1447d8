// fluxcal compare calibration.json map.csv [--region IDMIN:IDMAX,IQMIN:IQMAX] [--sym]
//                 [--convention C] [--current S] [--flux-amplitude S] [--units U] [--json]
// Flux error of a calibration against a flux map's nodes (io/flux_map.h)
// inside a current region (default: the calibration's measured region):
// RMS and maximum of |psi_cal - psi_map|, absolute in Wb and relative to the
// largest |psi| among those nodes, per-axis RMS and the worst node.
// --sym compares against the publisher's symmetrised columns
// (psi_d_sym_*, psi_q_sym_*) instead of the raw ones. The map is read in
// the convention the flags name (cli/support_flux_map.h; default: detected)
// and refused when implausible (io/flux_map.h).
#include <cmath>
#include <cstdio>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_flux_map.h"
#include "io/flux_map.h"
#include "nlohmann/json.hpp"
#include "pipeline/flux_map.h"
#include "pipeline/pipeline.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("compare", m, code); }

// "IDMIN:IDMAX,IQMIN:IQMAX", finite, min <= max on each axis.
bool ParseRegion(const std::string& s, tables::CurrentRegion* r) {
  std::vector<std::string> axes = absl::StrSplit(s, ',');
  if (axes.size() != 2) return false;
  double v[4];
  for (int a = 0; a < 2; ++a) {
    std::vector<std::string> f = absl::StrSplit(axes[a], ':');
    if (f.size() != 2 || !absl::SimpleAtod(f[0], &v[2 * a]) || !absl::SimpleAtod(f[1], &v[2 * a + 1])) return false;
    if (!std::isfinite(v[2 * a]) || !std::isfinite(v[2 * a + 1]) || v[2 * a] > v[2 * a + 1]) return false;
  }
  *r = {v[0], v[1], v[2], v[3]};
  return true;
}

const FlagSpecs kCompareFlags = [] {
  FlagSpecs f = {
      {"region", "IDMIN:IDMAX,IQMIN:IQMAX", "current region compared, A (default the calibration's measured region)"},
      {"sym", "", "compare against the map's symmetrised columns (psi_d_sym_*, psi_q_sym_*) instead of the raw ones"},
      kJsonFlag,
  };
  for (const auto& c : FluxMapConventionFlags()) f.push_back(c);
  return f;
}();

int RunCompare(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kCompareFlags);
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  if (args->positional.size() != 2) {
    return Fail("usage: fluxcal compare calibration.json map.csv [--region IDMIN:IDMAX,IQMIN:IQMAX] [--sym] "
                "[--convention C] [--current S] [--flux-amplitude S] [--units U] [--json]",
                2);
  }
  auto convention = FluxMapConventionFromArgs(*args);
  if (!convention.ok()) return Fail(std::string(convention.status().message()), 2);
  tables::CurrentRegion region;
  const bool region_given = args->Get("region").has_value();
  if (region_given && !ParseRegion(*args->Get("region"), &region)) {
    return Fail("flag --region: expected IDMIN:IDMAX,IQMIN:IQMAX (finite numbers, min <= max), got '" +
                    *args->Get("region") + "'",
                2);
  }
  const std::string cal_path = args->positional[0], map_path = args->positional[1];
  auto cal = pipeline::LoadCalibrationFile(cal_path);
  if (!cal.ok()) return Fail(std::string(cal.status().message()));
  io::FluxMapReadOptions ro;
  ro.columns = args->Has("sym") ? io::FluxMapColumns::kSymmetrised : io::FluxMapColumns::kRaw;
  ro.convention = *convention;
  auto map = io::ReadFluxMapCsv(map_path, ro);
  if (!map.ok()) return Fail(std::string(map.status().message()));
  std::fprintf(stderr, "compare: map %s: %s\n", map_path.c_str(), map->convention.Describe().c_str());
  if (!region_given) region = pipeline::MeasuredCurrentRegion(*cal);
  std::fprintf(stderr, "compare: map %s, %zu x %zu nodes; region id %g..%g A, iq %g..%g A (%s)\n", map_path.c_str(),
               map->id_a.size(), map->iq_a.size(), region.id_min_a, region.id_max_a, region.iq_min_a,
               region.iq_max_a, region_given ? "--region" : "the calibration's measured region");
  auto c = pipeline::CompareWithFluxMap(*cal, *map, region);
  if (!c.ok()) return Fail(std::string(c.status().message()));
  const double worst_rel = c->psi_scale_wb > 0 ? c->max_wb / c->psi_scale_wb : 0.0;
  if (args->Has("json")) {
    nlohmann::json j = {
        {"calibration", cal_path},
        {"serial", cal->serial()},
        {"model", cal->family().Name()},
        {"map", map_path},
        {"columns", args->Has("sym") ? "sym" : "raw"},
        {"convention", FluxMapConventionJson(map->convention)},
        {"region",
         {{"id_min_a", region.id_min_a}, {"id_max_a", region.id_max_a}, {"iq_min_a", region.iq_min_a},
          {"iq_max_a", region.iq_max_a}, {"source", region_given ? "flag" : "measured"}}},
        {"nodes", c->nodes},
        {"psi_scale_wb", c->psi_scale_wb},
        {"rms_relative", c->rms_relative},
        {"max_relative", c->max_relative},
        {"rms_wb", c->rms_wb},
        {"max_wb", c->max_wb},
        {"rms_d_wb", c->rms_d_wb},
        {"rms_q_wb", c->rms_q_wb},
        {"worst",
         {{"id_a", c->worst.id_a}, {"iq_a", c->worst.iq_a}, {"error_wb", c->max_wb}, {"error_relative", worst_rel},
          {"error_d_wb", c->worst_error_d_wb}, {"error_q_wb", c->worst_error_q_wb},
          {"map_psi_d_wb", c->worst.psi_d_wb}, {"map_psi_q_wb", c->worst.psi_q_wb}}}};
    PrintJson(j);
  } else {
    std::printf("serial %s (%s) against %s (%s columns): %d nodes in id %g..%g A, iq %g..%g A\n",
                cal->serial().c_str(), cal->family().Name().c_str(), map_path.c_str(),
                args->Has("sym") ? "sym" : "raw", c->nodes, region.id_min_a, region.id_max_a, region.iq_min_a,
                region.iq_max_a);
    std::printf("  flux error: RMS %.3f %% (%.3g Wb), max %.3f %% (%.3g Wb) of the largest |psi| %.4g Wb\n",
                100 * c->rms_relative, c->rms_wb, 100 * c->max_relative, c->max_wb, c->psi_scale_wb);
    std::printf("  per axis RMS: psi_d %.3g Wb, psi_q %.3g Wb\n", c->rms_d_wb, c->rms_q_wb);
    std::printf("  worst node: id %g A, iq %g A: %.3g Wb (psi_d %+.3g Wb, psi_q %+.3g Wb, calibration - map)\n",
                c->worst.id_a, c->worst.iq_a, c->max_wb, c->worst_error_d_wb, c->worst_error_q_wb);
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("compare", "flux error of a calibration against a flux map (CSV grid) in a current region",
                         RunCompare,
                         "fluxcal compare calibration.json map.csv [--region IDMIN:IDMAX,IQMIN:IQMAX] [--sym] "
                         "[--convention C] [--current S] [--flux-amplitude S] [--units U] [--json]",
                         kCompareFlags);

}  // namespace fluxcal::cli
