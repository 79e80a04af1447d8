// fluxcal map export calibration.json --out map.csv [--grid IDMIN:IDMAX:N,IQMIN:IQMAX:M]
//                   [--inverse [--psi-grid PDMIN:PDMAX:N,PQMIN:PQMAX:M]] [--force] [--json]
// Writes a calibration as a flux map the field's tools read
// (tables/flux_map_export.h):
//   default    psi(id, iq) on a current grid, `id_A,iq_A,psi_d_Vs,psi_q_Vs`
//              (default grid: the measured region, 21 x 21 nodes), in
//              fluxcal's convention (d = magnet axis, peak currents, Vs);
//   --inverse  i(psi_d, psi_q) on a flux grid, `psi_d_Vs,psi_q_Vs,id_A,iq_A,valid`
//              (default grid: the flux range over the measured region,
//              21 x 21; nodes without a solution there are valid = 0).
// Never overwrites an existing file unless --force.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "io/csv.h"
#include "io/flux_map.h"
#include "nlohmann/json.hpp"
#include "pipeline/flux_map.h"
#include "pipeline/pipeline.h"
#include "io/sha256.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("map export", m, code); }

// "MIN:MAX:N,MIN:MAX:M" -> two axes (checked again by the library).
bool ParseGrid(const std::string& s, tables::LinearAxis* a, tables::LinearAxis* b) {
  std::vector<std::string> axes = absl::StrSplit(s, ',');
  if (axes.size() != 2) return false;
  for (int k = 0; k < 2; ++k) {
    tables::LinearAxis* ax = k == 0 ? a : b;
    std::vector<std::string> f = absl::StrSplit(axes[k], ':');
    if (f.size() != 3 || !absl::SimpleAtod(f[0], &ax->min) || !absl::SimpleAtod(f[1], &ax->max) ||
        !absl::SimpleAtoi(f[2], &ax->n)) {
      return false;
    }
  }
  return true;
}

nlohmann::json AxisJson(const tables::LinearAxis& a) { return {{"min", a.min}, {"max", a.max}, {"n", a.n}}; }

const FlagSpecs kMapExportFlags = {
    OutFlag("flux map CSV"),
    {"grid", "IDMIN:IDMAX:N,IQMIN:IQMAX:M", "current grid of the forward map, A (default the measured region, 21 x 21)"},
    {"inverse", "", "write the inverse map i(psi) instead of psi(id, iq)"},
    {"psi-grid", "PDMIN:PDMAX:N,PQMIN:PQMAX:M", "with --inverse: flux grid, Wb (default the fluxes of the measured region)"},
    JsonFlag("a summary (nodes, sha256)"),
    kForceFlag,
};

int RunMapExport(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kMapExportFlags);
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  const char* usage =
      "usage: fluxcal map export calibration.json --out map.csv [--grid IDMIN:IDMAX:N,IQMIN:IQMAX:M] "
      "[--inverse [--psi-grid PDMIN:PDMAX:N,PQMIN:PQMAX:M]] [--force] [--json]";
  if (args->positional.size() != 1 || !args->Get("out")) return Fail(usage, 2);
  if (auto e = CheckOutToStdout(*args); !e.empty()) return Fail(e, 2);
  const bool to_stdout = *args->Get("out") == "-";
  const bool inverse = args->Has("inverse");
  if (inverse && args->Get("grid")) return Fail("--grid is the current grid of a forward map; with --inverse use --psi-grid", 2);
  if (!inverse && args->Get("psi-grid")) return Fail("--psi-grid needs --inverse", 2);
  const std::string out = *args->Get("out");
  auto cal = pipeline::LoadCalibrationFile(args->positional[0]);
  if (!cal.ok()) return Fail(std::string(cal.status().message()));

  tables::LinearAxis a, b;
  const char* grid_flag = inverse ? "psi-grid" : "grid";
  if (auto g = args->Get(grid_flag)) {
    if (!ParseGrid(*g, &a, &b)) {
      return Fail(std::string("flag --") + grid_flag + ": expected MIN:MAX:N,MIN:MAX:M, got '" + *g + "'", 2);
    }
  } else {
    pipeline::DefaultFluxMapGrid(*cal, inverse, &a, &b);
  }

  // Every flag checked: the overwrite rule (cli/args.h), before any work.
  if (auto e = CheckOverwrite(*args, {{"out", out}}); !e.empty()) return Fail(e);
  std::string text;
  nlohmann::json summary = {{"out", out}, {"serial", cal->serial()}, {"model", cal->family().Name()},
                            {"kind", inverse ? "inverse" : "forward"}};
  size_t rows = 0;
  if (inverse) {
    std::fprintf(stderr, "map export: inverse map on psi_d %g..%g Wb (%d) x psi_q %g..%g Wb (%d)\n", a.min, a.max,
                 a.n, b.min, b.max, b.n);
    auto inv = pipeline::ExportFluxMap(*cal, a, b, /*inverse=*/true);
    if (!inv.ok()) return Fail("flag --psi-grid: " + std::string(inv.status().message()), 2);
    text = std::move(inv->csv);
    rows = inv->rows;
    summary["grid"] = {{"psi_d_wb", AxisJson(a)}, {"psi_q_wb", AxisJson(b)}};
    summary["valid"] = inv->valid_nodes;
    summary["invalid"] = rows - inv->valid_nodes;
  } else {
    std::fprintf(stderr, "map export: flux map on id %g..%g A (%d) x iq %g..%g A (%d)\n", a.min, a.max, a.n, b.min,
                 b.max, b.n);
    auto m = pipeline::ExportFluxMap(*cal, a, b, /*inverse=*/false);
    if (!m.ok()) {
      const std::string msg(m.status().message());
      return msg.rfind("field 'grid", 0) == 0 ? Fail("flag --grid: " + msg, 2) : Fail(msg);
    }
    text = std::move(m->csv);
    rows = m->rows;
    summary["grid"] = {{"id_a", AxisJson(a)}, {"iq_a", AxisJson(b)}};
    summary["extrapolated"] = m->extrapolated;
    // What the file is in (io/flux_map.h): readers of other tools need it;
    // fluxcal's own reader detects it from the node at zero current.
    summary["convention"] = {{"axes", "fluxcal"}, {"current", "peak"}, {"flux_unit", "Vs"}};
    if (!m->zero_current_node) {
      std::fprintf(stderr, "map export: the grid has no node at zero current: read the file back with "
                           "--convention fluxcal (the axes cannot be detected without it)\n");
    }
  }
  if (auto st = WriteNewOutput(*args, {"out", out}, text); !st.ok()) return Fail(std::string(st.message()));
  const std::string sha = io::Sha256Hex(text);
  summary["rows"] = rows;
  summary["bytes"] = text.size();
  summary["sha256"] = sha;
  if (args->Has("json")) {
    PrintJson(summary);
  } else if (inverse) {
    std::fprintf(to_stdout ? stderr : stdout, "%s: inverse flux map of %s, %zu nodes (%d valid), sha256 %s\n", out.c_str(), cal->serial().c_str(),
                rows, summary["valid"].get<int>(), sha.c_str());
  } else {
    std::fprintf(to_stdout ? stderr : stdout, "%s: flux map of %s, %zu nodes (%d extrapolated), sha256 %s\n", out.c_str(), cal->serial().c_str(),
                rows, summary["extrapolated"].get<int>(), sha.c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("map export", "write a calibration as a flux map psi(id, iq) or its inverse i(psi) (CSV)",
                         RunMapExport,
                         "fluxcal map export calibration.json --out map.csv [--grid IDMIN:IDMAX:N,IQMIN:IQMAX:M] [--force] [--json]\n"
                         "fluxcal map export calibration.json --inverse --out imap.csv [--psi-grid PDMIN:PDMAX:N,PQMIN:PQMAX:M] [--force] [--json]",
                         kMapExportFlags);

}  // namespace fluxcal::cli
