// fluxcal eol <recording-set> --server ADDR [--station ID] [--model M]
//             [--tables-dir DIR] [--upload-recording] [--json]
// The EOL station flow (pipeline/eol_station.h): identify every point
// locally, stream the results for the serial, (with --upload-recording)
// upload the raw set, ask for a fit and its verdict, fetch the ECU tables.
// Each stream declares its end (count and SHA-256 of what it carries), and
// the reply's count and digest of what the service stored must equal what
// was sent, or eol stops (exit 1) before anything is fitted. Here: flags,
// the stub, the table files and the summary.
#include <thread>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include <grpcpp/grpcpp.h>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_remote.h"
#include "io/recording_set.h"
#include "io/sha256.h"
#include "pipeline/eol_station.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
namespace {

const FlagSpecs kEolFlags = {
    kServerFlag,
    {"station", "ID", "station id recorded with the run (default eol)"},
    {"model", "M", "model family the service fits, as `fluxcal fit --model` (default auto)"},
    {"tables-dir", "DIR", "on a pass, fetch the MTPA (CDFX) and field-weakening (DCM) tables there"},
    {"upload-recording", "", "also upload the raw waveforms (replayable on the service)"},
    kJsonFlag,
    {kForceFlag.name, kForceFlag.value, "replace table files in --tables-dir that exist (refused otherwise)"},
};

int RunEol(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kEolFlags);
  if (!args.ok() || args->positional.size() != 1 || !args->Get("server")) {
    return UsageError("fluxcal eol <recording-set> --server ADDR [--station ID] [--model M] "
                      "[--tables-dir DIR [--force]] [--upload-recording] [--json]");
  }
  auto set = io::ReadRecordingSet(args->positional[0]);
  if (!set.ok()) return CommandError("eol", std::string(set.status().message()));
  const std::string serial = set->manifest.serial;
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  // The flow is pipeline::RunEolStation; here: its options from the flags,
  // the tables written under the overwrite rule, the summary printed.
  pipeline::EolStationOptions o;
  o.station_id = args->Get("station").value_or("eol");
  o.model = args->Get("model").value_or("auto");
  if (args->Has("upload-recording")) o.upload_recording_dir = args->positional[0];
  o.log = [](const std::string& line) { std::fprintf(stderr, "%s\n", line.c_str()); };
  nlohmann::json tables = nlohmann::json::array();
  const auto dir = args->Get("tables-dir");
  o.fetch_tables = dir.has_value();
  bool dir_made = false;
  o.on_table = [&](const std::string& table, const std::string& format,
                   const v1::ExportTableResponse& resp) -> absl::Status {
    if (!dir_made) std::filesystem::create_directories(*dir);
    dir_made = true;
    const std::string path = *dir + "/" + serial + "_v" + std::to_string(resp.version()) + "_" + table + "." + format;
    // Named by serial and stored version, which a store never reuses: a
    // file already there came from another store (the overwrite rule,
    // cli/args.h, applies when the names are known, i.e. here).
    if (auto st = WriteNewOutput(*args, {"tables-dir", path}, resp.data()); !st.ok()) return st;
    // sha256 of the file written (= sha256sum); crc32/sha256 of the reply are over the values.
    tables.push_back({{"path", path}, {"sha256", io::Sha256Hex(resp.data())},
                      {"payload_crc32", resp.crc32()}, {"payload_sha256", resp.sha256()}});
    return absl::OkStatus();
  };
  grpc::Status rpc_error;
  auto r = pipeline::RunEolStation(*stub, *set, o, &rpc_error);
  if (!r.ok()) {
    if (!rpc_error.ok()) return ReportRpcError("eol", rpc_error);
    return CommandError("eol", std::string(r.status().message()));
  }
  const v1::IngestHfResultsResponse& ing = r->ingest;
  const v1::FitResponse& fit = r->fit;
  nlohmann::json out = {{"serial", serial}, {"run_id", ing.run_id()}, {"accepted", ing.accepted()},
                        {"rejected", ing.rejects_size()} /* always 0: a bad point fails the stream */,
                        {"points_sha256", ing.points_sha256()}, {"version", fit.calibration().version()},
                        {"model", fit.calibration().model()}, {"verdict", fit.calibration().verdict()},
                        {"pass", fit.pass()}, {"psi_pm_wb", fit.calibration().psi_pm_wb()},
                        {"rms_relative", fit.calibration().rms_relative()}, {"tables", tables}};
  if (const auto& rec = r->recording) {
    out["recording"] = {{"run_id", rec->run_id()}, {"points", rec->points()}, {"sha256", rec->recording_sha256()},
                        {"bytes", rec->recording_bytes()}, {"replayed", rec->replayed()}, {"files", rec->files()},
                        {"files_sha256", rec->files_sha256()}};
  }
  if (args->Has("json")) {
    PrintJson(out);
  } else {
    std::printf("%s: calibration v%d (%s), verdict %s, psi_pm %.5g Wb, fit rms %.3f %%\n", serial.c_str(),
                fit.calibration().version(), fit.calibration().model().c_str(), fit.calibration().verdict().c_str(),
                fit.calibration().psi_pm_wb(), 100 * fit.calibration().rms_relative());
    for (const auto& t : out["tables"]) std::printf("  %s payload_crc32 %s\n", t["path"].get<std::string>().c_str(), t["payload_crc32"].get<std::string>().c_str());
  }
  return fit.pass() ? 0 : 3;
}

constexpr char kListUsage[] = "fluxcal list --server ADDR [--prefix P] [--failed] [--json]";
const FlagSpecs kListFlags = {
    kServerFlag,
    {"prefix", "P", "only serials starting with P"},
    {"failed", "", "only motors whose latest verdict is a fail"},
    {"page-size", "N", "accepted for compatibility; has no effect (all pages are fetched)"},
    kJsonFlag,
};

int RunList(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kListFlags);
  if (!args.ok() || !args->Get("server")) return UsageError(kListUsage);
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  nlohmann::json all = nlohmann::json::array();
  std::string token;
  do {
    v1::ListMotorsRequest req;
    req.set_serial_prefix(args->Get("prefix").value_or(""));
    req.set_only_failed(args->Has("failed"));
    req.set_page_size(200);
    req.set_page_token(token);
    v1::ListMotorsResponse resp;
    auto s = CallWithDeadline(*stub, &v1::CalibrationService::Stub::ListMotors, req, &resp);
    if (!s.ok()) return ReportRpcError("list", s);
    for (const auto& m : resp.motors()) {
      all.push_back({{"serial", m.serial()}, {"latest_version", m.latest_version()}, {"verdict", m.verdict()},
                     {"runs", m.runs()}, {"updated_utc", m.updated_utc()}});
    }
    token = resp.next_page_token();
  } while (!token.empty());
  if (args->Has("json")) {
    PrintJson({{"motors", all}});
  } else {
    std::printf("%-24s %7s %5s  %-20s %s\n", "serial", "version", "runs", "updated", "verdict");
    for (const auto& m : all) {
      std::printf("%-24s %7d %5d  %-20s %s\n", m["serial"].get<std::string>().c_str(), m["latest_version"].get<int>(),
                  m["runs"].get<int>(), m["updated_utc"].get<std::string>().c_str(), m["verdict"].get<std::string>().c_str());
    }
  }
  return 0;
}

constexpr char kHistoryUsage[] = "fluxcal history SERIAL --server ADDR [--json]";
// history and fleet: the service's answer and nothing else to ask for.
const FlagSpecs kServerJsonFlags = {kServerFlag, kJsonFlag};

int PrintHistory(const v1::HistoryResponse& resp, bool json) {
  nlohmann::json ev = nlohmann::json::array();
  for (const auto& e : resp.events()) {
    ev.push_back({{"created_utc", e.created_utc()}, {"kind", e.kind()}, {"run_id", e.run_id()},
                  {"version", e.version()}, {"detail", e.detail()}});
  }
  if (json) {
    PrintJson({{"serial", resp.serial()}, {"events", ev}});
  } else {
    for (const auto& e : ev) {
      std::printf("%s  %-12s run %-5lld v%-3d %s\n", e["created_utc"].get<std::string>().c_str(),
                  e["kind"].get<std::string>().c_str(), static_cast<long long>(e["run_id"].get<int64_t>()),
                  e["version"].get<int>(), e["detail"].get<std::string>().c_str());
    }
  }
  return 0;
}

int RunHistory(const std::vector<std::string>& argv) {
  return RunSerialCall("history", kHistoryUsage, argv, kServerJsonFlags, &v1::CalibrationService::Stub::History,
                       PrintHistory);
}

constexpr char kFleetUsage[] = "fluxcal fleet --server ADDR [--json]";

int RunFleet(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kServerJsonFlags);
  if (!args.ok() || !args->Get("server")) return UsageError(kFleetUsage);
  v1::FleetStatisticsRequest req;
  v1::FleetStatisticsResponse resp;
  const std::string server = *args->Get("server");
  const auto rpc = &v1::CalibrationService::Stub::FleetStatistics;
  if (int rc = CallService("fleet", server, rpc, req, &resp, /*seconds=*/60); rc != 0) return rc;
  nlohmann::json pts = nlohmann::json::array();
  for (const auto& p : resp.points()) {
    pts.push_back({{"id_a", p.id_a()}, {"iq_a", p.iq_a()}, {"serials", p.serials()},
                   {"ldd_h_mean", p.ldd_h_mean()}, {"ldd_h_std", p.ldd_h_std()}, {"lqq_h_mean", p.lqq_h_mean()},
                   {"lqq_h_std", p.lqq_h_std()}, {"psi_d_wb_mean", p.psi_d_wb_mean()},
                   {"psi_d_wb_std", p.psi_d_wb_std()}, {"torque_nm_mean", p.torque_nm_mean()},
                   {"torque_nm_std", p.torque_nm_std()},
                   {"outliers", std::vector<std::string>(p.outliers().begin(), p.outliers().end())}});
  }
  if (args->Has("json")) {
    PrintJson({{"points", pts}});
  } else {
    for (const auto& p : pts) {
      std::printf("(%6.1f, %6.1f) A: %d serials, Ldd %.4f +- %.4f mH, Lqq %.4f +- %.4f mH, torque %.3f +- %.3f N m, outliers %s\n",
                  p["id_a"].get<double>(), p["iq_a"].get<double>(), p["serials"].get<int>(),
                  1e3 * p["ldd_h_mean"].get<double>(), 1e3 * p["ldd_h_std"].get<double>(),
                  1e3 * p["lqq_h_mean"].get<double>(), 1e3 * p["lqq_h_std"].get<double>(),
                  p["torque_nm_mean"].get<double>(), p["torque_nm_std"].get<double>(), p["outliers"].dump().c_str());
    }
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("eol", "EOL station: identify, stream to the service, fit, verdict, fetch tables", RunEol,
                         "fluxcal eol <recording-set> --server ADDR [--station ID] [--model M] [--tables-dir DIR] [--upload-recording] [--json]",
                         kEolFlags);
FLUXCAL_REGISTER_COMMAND("list", "list motors known to the service", RunList, kListUsage, kListFlags);
FLUXCAL_REGISTER_COMMAND("history", "a serial's runs and calibration versions", RunHistory, kHistoryUsage,
                         kServerJsonFlags);
FLUXCAL_REGISTER_COMMAND("fleet", "fleet statistics per operating point, outlier serials", RunFleet, kFleetUsage,
                         kServerJsonFlags);

}  // namespace fluxcal::cli
