// fluxcal diagnose <recording-set> [--json] [--plots DIR] [--exclude-effects a,b]
//                  [--calibration-out cal.json]
// fluxcal diagnose --table1 data/paper_table1.csv [--json]
// fluxcal diagnose SERIAL --server ADDR [--store] [--json]
// Locates where the nominal model and the recordings differ, names the
// missing physics, refits, reports (docs/diagnosis-report.md).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <iterator>
#include <set>
#include <system_error>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_remote.h"
#include "absl/strings/str_split.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"
#include "pipeline/diagnose.h"

namespace fluxcal::cli {
namespace {

const FlagSpecs kDiagnoseFlags = {
    {"plots", "DIR", "write the diagnosis figures (SVG) there"},
    {"exclude-effects", "A,B", "effects not to consider (names as in `fluxcal simulate --effects`)"},
    {"calibration-out", "FILE", "write the diagnosed model as a calibration JSON (refitted without the findings)"},
    {"table1", "CSV", "diagnose the paper's Table 1 instead of a recording set"},
    ServerFlag("diagnose a serial's stored raw recording at the service instead"),
    {"store", "", "with --server: store the diagnosed model as a new calibration version marked with the findings"},
    {"json", "", "print the diagnosis report as one JSON document (docs/diagnosis-report.md)"},
    kForceFlag,
};

// The figures --plots DIR holds.
const char* const kPlotFiles[] = {"residual_before.svg", "residual_after.svg", "replay_spectrum.svg"};

// fluxcal diagnose SERIAL --server ADDR [--store] [--json]: the service
// diagnoses the serial's latest stored raw recording (`eol
// --upload-recording` puts it there); with --store it keeps the diagnosed
// model as a new calibration version.
int RunRemoteDiagnose(const ParsedArgs& args, const std::string& server) {
  for (const char* local : {"plots", "exclude-effects", "calibration-out", "table1"}) {
    if (args.Has(local)) {
      std::fprintf(stderr, "fluxcal diagnose: flag --%s is local only (not with --server)\n", local);
      return 2;
    }
  }
  if (args.positional.size() != 1) {
    std::fprintf(stderr, "usage: fluxcal diagnose SERIAL --server ADDR [--store] [--json]\n");
    return 2;
  }
  auto stub = MakeStub(server);
  if (!stub) {
    std::fprintf(stderr, "fluxcal diagnose: --server %s: cannot set up the client\n", server.c_str());
    return 1;
  }
  v1::DiagnoseRequest req;
  req.set_serial(args.positional[0]);
  req.set_store_calibration(args.Has("store"));
  v1::DiagnoseResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::minutes(5));
  auto st = stub->Diagnose(&ctx, req, &resp);
  if (!st.ok()) return ReportRpcError("diagnose", st);
  if (args.Has("json")) {
    nlohmann::json j = nlohmann::json::parse(resp.report_json(), nullptr, false);
    if (j.is_discarded()) j = nlohmann::json::object();
    if (resp.stored_version() > 0) j["stored"] = {{"version", resp.stored_version()}, {"verdict", resp.stored_verdict()}};
    PrintJson(j);
  } else {
    std::printf("%s: %s", resp.serial().c_str(), resp.verdict().c_str());
    for (int k = 0; k < resp.effects_size(); ++k) std::printf("%s%s", k ? ", " : " (", resp.effects(k).c_str());
    std::printf("%s\n", resp.effects_size() ? ")" : "");
    if (resp.stored_version() > 0) {
      std::printf("stored as version %d: %s\n", resp.stored_version(), resp.stored_verdict().c_str());
    }
  }
  return 0;
}

int RunDiagnose(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kDiagnoseFlags);
  if (!args.ok()) {
    std::fprintf(stderr, "fluxcal diagnose: %s\n", std::string(args.status().message()).c_str());
    return 2;
  }
  if (auto t1 = args->Get("table1")) {
    auto table1 = pipeline::DiagnoseTable1File(*t1);
    if (!table1.ok()) {
      std::fprintf(stderr, "fluxcal diagnose: %s\n", std::string(table1.status().message()).c_str());
      return 1;
    }
    const auto& r = *table1;
    if (args->Has("json")) {
      PrintJson({{"finding", r.finding}, {"rms_before", r.rms_before}, {"rms_after", r.rms_after},
                 {"trend_slope_per_a", r.trend_slope_per_a}, {"trend_sigma", r.trend_sigma},
                 {"lq_app_from_hf_h", r.lq_app_from_hf_h},
                 {"max_before", r.max_before}, {"max_after", r.max_after},
                 {"alternatives", [&] {
                    nlohmann::json alts = nlohmann::json::array();
                    for (const auto& x : r.alternatives) {
                      alts.push_back({{"name", x.name}, {"meaning", x.meaning},
                                      {"parameter", x.parameter}, {"unit", x.unit},
                                      {"rms", x.rms}, {"max", x.max}, {"delta_bic", x.delta_bic}});
                    }
                    return alts;
                  }()}});
    } else {
      std::printf("Paper Table 1: HF Lq vs steady-state Lq: relative mismatch grows with iq (%.3g %%/A, %.1f sigma).\n"
                  "Finding: %s. RMS error %.2f %% with the differential Lq taken as apparent, %.2f %% with the apparent Lq\n"
                  "obtained by integrating the differential one.\n",
                  100 * r.trend_slope_per_a, r.trend_sigma, r.finding.empty() ? "none" : r.finding.c_str(),
                  100 * r.rms_before, 100 * r.rms_after);
      std::printf("Largest error %.2f %% -> %.2f %%. What else could explain the rest (rows with iq > 0):\n",
                  100 * r.max_before, 100 * r.max_after);
      for (const auto& x : r.alternatives) {
        std::printf("  %-16s %s: parameter %.4g %s, RMS %.2f %%, max %.2f %%, delta BIC %+.1f\n", x.name.c_str(),
                    x.meaning.c_str(), x.parameter, x.unit.c_str(), 100 * x.rms, 100 * x.max, x.delta_bic);
      }
    }
    return 0;
  }
  if (auto server = args->Get("server")) return RunRemoteDiagnose(*args, *server);
  if (args->Has("store")) {
    std::fprintf(stderr, "fluxcal diagnose: flag --store needs --server\n");
    return 2;
  }
  if (args->positional.size() != 1) {
    std::fprintf(stderr, "usage: fluxcal diagnose <recording-set> [--json] [--plots DIR] [--exclude-effects a,b]\n"
                         "       [--calibration-out cal.json] [--force]\n"
                         "       fluxcal diagnose --table1 data/paper_table1.csv [--json]\n");
    return 2;
  }
  // The overwrite rule (cli/args.h), before the (slow) diagnosis.
  std::vector<OutputPath> outputs;
  if (auto out = args->Get("calibration-out")) outputs.push_back({"calibration-out", *out});
  if (auto dir = args->Get("plots")) {
    for (const char* f : kPlotFiles) outputs.push_back({"plots", *dir + "/" + f});
  }
  if (auto e = CheckOverwrite(*args, outputs); !e.empty()) {
    std::fprintf(stderr, "fluxcal diagnose: %s\n", e.c_str());
    return 1;
  }
  auto set = io::ReadRecordingSet(args->positional[0]);
  if (!set.ok()) {
    std::fprintf(stderr, "fluxcal diagnose: %s\n", std::string(set.status().message()).c_str());
    return 1;
  }
  std::fprintf(stderr, "diagnose %s: %zu points, %zu steady-state rows\n", set->manifest.serial.c_str(),
               set->waveforms.size(), set->steady_state.size());
  std::set<std::string> excluded;
  if (auto ex = args->Get("exclude-effects")) {
    for (const std::string& name : std::vector<std::string>(absl::StrSplit(*ex, ',', absl::SkipEmpty()))) {
      if (!pipeline::IsKnownEffect(name)) {
        std::fprintf(stderr, "fluxcal diagnose: flag --exclude-effects: unknown effect '%s'\n", name.c_str());
        return 2;
      }
      excluded.insert(name);
    }
  }
  auto rep = pipeline::DiagnoseSet(*set, excluded);
  if (!rep.ok()) {
    std::fprintf(stderr, "fluxcal diagnose: %s\n", std::string(rep.status().message()).c_str());
    return 1;
  }
  if (auto dir = args->Get("plots")) {
    std::error_code ec;
    std::filesystem::create_directories(*dir, ec);
    const auto svgs = pipeline::DiagnosisFigures(*rep);
    for (size_t k = 0; k < std::size(svgs); ++k) {
      if (auto st = WriteNewOutput(*args, {"plots", *dir + "/" + kPlotFiles[k]}, svgs[k]); !st.ok()) {
        std::fprintf(stderr, "fluxcal diagnose: %s\n", std::string(st.message()).c_str());
        return 1;
      }
    }
    std::fprintf(stderr, "diagnose: plots in %s\n", dir->c_str());
  }
  if (auto out = args->Get("calibration-out")) {
    // The diagnosed model as a calibration (fitting's families, refitted on
    // the data freed of the findings), marked with what was found.
    auto marked = pipeline::DiagnosedCalibrationJson(*rep);
    if (!marked.ok()) {
      std::fprintf(stderr, "fluxcal diagnose: %s\n", std::string(marked.status().message()).c_str());
      return 1;
    }
    const nlohmann::json& j = *marked;
    if (auto st = WriteNewOutput(*args, {"calibration-out", *out},
                                 j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n");
        !st.ok()) {
      std::fprintf(stderr, "fluxcal diagnose: %s\n", std::string(st.message()).c_str());
      return 1;
    }
    std::fprintf(stderr, "diagnose: calibration (%s) in %s\n", j.value("model", std::string("?")).c_str(), out->c_str());
  }
  if (args->Has("json")) PrintJson(pipeline::DiagnosisJson(*rep));
  else std::cout << pipeline::DiagnosisText(*rep);
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("diagnose", "locate, explain and model what the set's own calibration and the twin miss", RunDiagnose,
                         "fluxcal diagnose <recording-set> [--json] [--plots DIR] [--exclude-effects a,b] [--calibration-out cal.json] [--force]\n"
                         "fluxcal diagnose --table1 data/paper_table1.csv [--json]",
                         kDiagnoseFlags);

}  // namespace fluxcal::cli
