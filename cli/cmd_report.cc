// fluxcal report calibration.json [--set RECORDING_SET_DIR [--diagnose]] [--diagnosis report.json]
//                [--map MAP.csv [--convention C] ...] [--speed-rpm N] [--udc-v V] --out report.html [--json]
// fluxcal report SERIAL --server ADDR [--version N] [--speed-rpm N] [--udc-v V]
//                [--set DIR [--diagnose]] [--diagnosis FILE] [--map MAP.csv] --out report.html [--json]
// One self-contained static HTML page per calibration (report/report.h,
// docs/report.md). With --set the set is identified again so that the
// page shows the identified points against the fitted surfaces, the
// verdict is judged as the EOL flow judges it, and the manifest's DC-link
// voltage sets the voltage limit (else the calibration's Udc; with none the
// page says that the voltage limit cannot be drawn); --diagnose runs the
// diagnosis of the set here and embeds its residual maps and spectrum.
// --map draws a flux map's nodes over the surfaces. With --server the service builds the
// page from what only the store knows (when the version was created, its
// stored verdict, whether it is released for flashing, the fleet) with its
// GetReport, and the page is written as it arrived: one page per stored
// version, whoever asks. --set, --diagnosis and --map are local files the
// service never sees: with them the page is built here, from the stored calibration
// and the same provenance and fleet read over the API, as before GetReport
// existed (pipeline/report.h holds what both ways share).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>

#include "absl/strings/numbers.h"

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_flux_map.h"
#include "cli/support_progress.h"
#include "cli/support_remote.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "io/sha256.h"
#include "nlohmann/json.hpp"
#include "pipeline/pipeline.h"
#include "pipeline/points.h"
#include "pipeline/report.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("report", m, code); }

std::string FileMtimeUtc(const std::string& path) {
  std::error_code ec;
  const auto t = std::filesystem::last_write_time(path, ec);
  if (ec) return "unknown";
  const auto sys = std::chrono::file_clock::to_sys(t);
  const std::time_t tt = std::chrono::system_clock::to_time_t(sys);
  std::tm tm{};
  gmtime_r(&tt, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

absl::StatusOr<nlohmann::json> ReadJson(const std::string& path) {
  auto text = io::ReadFileToString(path);
  if (!text.ok()) return text.status();
  try {
    return nlohmann::json::parse(*text);
  } catch (const nlohmann::json::exception& e) {
    return absl::InvalidArgumentError(path + ": not JSON: " + e.what());
  }
}

// --server with local extras: the stored calibration with the store's
// provenance merged into its JSON, read over the API.
absl::StatusOr<nlohmann::json> FetchCalibration(const std::string& server, const std::string& serial, int version) {
  auto stub = MakeStub(server);
  if (!stub) return absl::InvalidArgumentError("--server " + server + ": cannot set up the client");
  v1::GetCalibrationRequest req;
  req.set_serial(serial);
  req.set_version(version);
  v1::CalibrationRecord rec;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto s = stub->GetCalibration(&ctx, req, &rec);
  if (!s.ok()) {
    ReportRpcError("report", s);   // the status, with a hint for setup mistakes
    return absl::UnavailableError("GetCalibration " + serial + " failed");
  }
  nlohmann::json j = nlohmann::json::parse(rec.calibration_json(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    return absl::DataLossError("stored calibration of " + serial + " is not a JSON object");
  }
  // The release flag comes with a table export; a caller without the
  // right to export unreleased versions learns nothing, and the page says
  // the state is not known.
  std::optional<bool> released;
  v1::ExportTableRequest er;
  er.set_serial(serial);
  er.set_version(rec.version());
  er.set_table("mtpa");
  er.set_format("csv");
  v1::ExportTableResponse eresp;
  grpc::ClientContext ectx;
  ectx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  if (stub->ExportTable(&ectx, er, &eresp).ok()) released = eresp.released();
  pipeline::MergeStoredProvenance(rec.version(), rec.created_utc(), rec.verdict(), released, &j);
  return j;
}

// --server with local extras: the service's fleet statistics at its
// default operating points.
absl::StatusOr<std::vector<pipeline::FleetPoint>> FetchFleet(const std::string& server) {
  auto stub = MakeStub(server);
  if (!stub) return absl::InvalidArgumentError("--server " + server + ": cannot set up the client");
  v1::FleetStatisticsRequest req;
  v1::FleetStatisticsResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto s = stub->FleetStatistics(&ctx, req, &resp);
  if (!s.ok()) return absl::UnavailableError("FleetStatistics: " + s.error_message());
  std::vector<pipeline::FleetPoint> points;
  for (const auto& p : resp.points()) {
    pipeline::FleetPoint f;
    f.id_a = p.id_a(); f.iq_a = p.iq_a(); f.serials = p.serials();
    f.ldd_h_mean = p.ldd_h_mean(); f.ldd_h_std = p.ldd_h_std();
    f.lqq_h_mean = p.lqq_h_mean(); f.lqq_h_std = p.lqq_h_std();
    f.psi_d_wb_mean = p.psi_d_wb_mean(); f.psi_d_wb_std = p.psi_d_wb_std();
    f.torque_nm_mean = p.torque_nm_mean(); f.torque_nm_std = p.torque_nm_std();
    f.outliers.assign(p.outliers().begin(), p.outliers().end());
    points.push_back(std::move(f));
  }
  return points;
}

// What every mode prints once the page is written.
struct Written {
  std::string out, serial, verdict, sha256;
  int version = 0, figures = 0;
  size_t bytes = 0;
  double voltage_limit_speed_rpm = 0;
};

void PrintSummary(const Written& w, bool json) {
  if (json) {
    PrintJson({{"out", w.out}, {"serial", w.serial}, {"version", w.version},
               {"verdict", w.verdict}, {"figures", w.figures}, {"bytes", w.bytes},
               {"voltage_limit_speed_rpm", w.voltage_limit_speed_rpm}, {"sha256", w.sha256}});
  } else {
    std::fprintf(w.out == "-" ? stderr : stdout, "%s: report for %s v%d (%s), %d figures, %zu bytes\n", w.out.c_str(),
                 w.serial.c_str(), w.version, w.verdict.c_str(), w.figures, w.bytes);
  }
}

// --server: the service's page (GetReport), its SHA-256 checked, written
// byte for byte.
int RunRemoteReport(const ParsedArgs& args, const std::string& server, const std::string& serial, int version,
                    double speed_rpm, std::optional<double> udc_v, const std::string& out, bool json) {
  auto stub = MakeStub(server);
  if (!stub) return Fail("--server " + server + ": cannot set up the client");
  v1::GetReportRequest req;
  req.set_serial(serial);
  req.set_version(version);
  req.set_speed_rpm(speed_rpm);
  if (udc_v) req.set_udc_v(*udc_v);
  v1::GetReportResponse resp;
  grpc::ClientContext ctx;
  // Tables, figures and the fleet over every serial: about a second on a
  // small store, more with a large fleet.
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  std::fprintf(stderr, "report: the service builds the page for %s\n", serial.c_str());
  if (auto s = stub->GetReport(&ctx, req, &resp); !s.ok()) return ReportRpcError("report", s);
  if (const std::string got = io::Sha256Hex(resp.html()); got != resp.html_sha256()) {
    return Fail("GetReport " + serial + ": the page arrived damaged (SHA-256 " + got + ", the service sent " +
                resp.html_sha256() + "); nothing written");
  }
  if (!resp.fleet_included()) {
    std::fprintf(stderr, "fluxcal report: no fleet comparison: the service shows it to roles that may read fleet "
                         "statistics (engineer, admin)\n");
  }
  if (auto st = WriteNewOutput(args, {"out", out}, resp.html()); !st.ok()) return Fail(std::string(st.message()));
  PrintSummary({out, resp.serial(), resp.verdict(), resp.html_sha256(), resp.version(), resp.figures(),
                resp.html().size(), resp.voltage_limit_speed_rpm()},
               json);
  return 0;
}

FlagSpecs ReportFlags() {
  FlagSpecs flags = {
    OutFlag("HTML page"),
    {"server", "ADDR",
     "the positional argument is a SERIAL stored there, HOST[:PORT] (default port 50051); the service builds the page"},
    kServerVersionFlag,
    {"set", "DIR",
     "recording set: draws the identified points, judges the verdict, gives the DC-link voltage "
     "(with --server: page built here)"},
    {"diagnose", "", "with --set: run the diagnosis of the set here and embed it with its residual maps and spectrum"},
    {"diagnosis", "FILE", "a `fluxcal diagnose --json` document to include (with --server: page built here)"},
    {"map", "CSV", "a flux map whose nodes are drawn over the fitted surfaces (with --server: page built here)"},
    {"speed-rpm", "RPM", "speed of the voltage-limit curve, mechanical rpm (default 1.5 x base speed)"},
    {"udc-v", "V", "DC-link voltage, V (default the set's manifest drive.udc_v, else the calibration's; none: no "
                   "voltage limit or field weakening drawn)"},
    JsonFlag("a summary (verdict, figures, bytes, sha256)"),
    kForceFlag,
  };
  for (auto c : FluxMapConventionFlags()) {
    c.help = "with --map: " + c.help;
    flags.push_back(std::move(c));
  }
  return flags;
}
const FlagSpecs kReportFlags = ReportFlags();

// A positive finite flag value, or none; InvalidArgument naming the flag.
absl::StatusOr<std::optional<double>> PositiveFlag(const ParsedArgs& args, const char* flag) {
  auto v = args.GetDouble(flag);
  if (!v.ok() || !v->has_value()) return v;
  if (!(**v > 0) || !std::isfinite(**v)) {
    return absl::InvalidArgumentError(std::string("flag --") + flag + ": must be a positive number");
  }
  return v;
}

int RunReport(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kReportFlags);
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  if (auto e = CheckOutToStdout(*args); !e.empty()) return Fail(e, 2);
  if (args->positional.size() != 1 || !args->Get("out")) {
    return Fail("usage: fluxcal report calibration.json [--set RECORDING_SET_DIR [--diagnose]] [--diagnosis "
                "report.json] [--map MAP.csv] [--speed-rpm N] [--udc-v V] --out report.html [--json]\n"
                "       fluxcal report SERIAL --server ADDR [--version N] [--speed-rpm N] [--udc-v V] "
                "[--set DIR [--diagnose]] [--diagnosis FILE] [--map MAP.csv] --out report.html [--json]", 2);
  }
  if (args->Has("diagnose") && !args->Get("set")) return Fail("flag --diagnose needs --set (the set to diagnose)", 2);
  if (args->Has("diagnose") && args->Get("diagnosis")) {
    return Fail("flags --diagnose and --diagnosis: one diagnosis per page (run here, or the document given)", 2);
  }
  if (!args->Get("map") && HasFluxMapConventionFlag(*args)) {
    return Fail("flags --convention, --current, --flux-amplitude and --units describe a flux map: they need --map", 2);
  }
  auto convention = FluxMapConventionFromArgs(*args);
  if (!convention.ok()) return Fail(std::string(convention.status().message()), 2);
  const bool local_extras = args->Has("set") || args->Has("diagnosis") || args->Has("map");
  const std::string cal_path = args->positional[0];
  const std::string out = *args->Get("out");
  auto speed = PositiveFlag(*args, "speed-rpm");
  if (!speed.ok()) return Fail(std::string(speed.status().message()), 2);
  auto udc = PositiveFlag(*args, "udc-v");
  if (!udc.ok()) return Fail(std::string(udc.status().message()), 2);
  int version = 0;
  if (auto v = args->Get("version")) {
    if (!args->Get("server")) return Fail("flag --version needs --server", 2);
    if (!absl::SimpleAtoi(*v, &version) || version < 0) return Fail("flag --version: expected a non-negative integer", 2);
  }
  // Every flag checked: the overwrite rule (cli/args.h), before any work.
  if (auto e = CheckOverwrite(*args, {{"out", out}}); !e.empty()) return Fail(e);

  absl::StatusOr<nlohmann::json> cal_json;
  std::string source, source_fleet, mtime = "unknown";
  std::optional<std::vector<pipeline::FleetPoint>> fleet;
  if (auto server = args->Get("server")) {
    if (!local_extras) {
      return RunRemoteReport(*args, *server, cal_path, version, speed->value_or(0.0), *udc, out, args->Has("json"));
    }
    std::fprintf(stderr, "report: --set/--diagnosis/--map are local: the page is built here, not by the service\n");
    cal_json = FetchCalibration(*server, cal_path, version);
    if (!cal_json.ok()) return Fail(std::string(cal_json.status().message()));
    source = cal_path + " from the service at " + *server;
    if (auto f = FetchFleet(*server); f.ok()) {
      fleet = std::move(*f);
    } else {
      std::fprintf(stderr, "fluxcal report: no fleet comparison: %s\n", std::string(f.status().message()).c_str());
    }
    source_fleet = "FleetStatistics of the service at " + *server + " (latest calibration of every serial)";
  } else {
    cal_json = ReadJson(cal_path);
    source = cal_path;
    mtime = FileMtimeUtc(cal_path);
  }
  if (!cal_json.ok()) return Fail(std::string(cal_json.status().message()));
  auto cal = pipeline::ParseCalibrationJson(*cal_json);
  if (!cal.ok()) return Fail(source + ": " + std::string(cal.status().message()));

  // Verdict, the findings of a diagnosed calibration and the software
  // version as the service's page takes them; a set or a diagnosis
  // document given here replaces them below.
  report::ReportInputs in;
  pipeline::FillReportInputsFromJson(*cal, *cal_json, &in);
  in.calibration_path = source;
  in.calibration_file_mtime_utc = mtime;
  if (fleet) {
    in.fleet = std::move(*fleet);
    in.fleet_source = source_fleet;
  }
  in.ellipse_speed_rpm = speed->value_or(0.0);
  if (*udc) {
    in.udc_v = **udc;
    in.udc_source = pipeline::kUdcFromRequest;
  }

  // The set's points, Udc and verdict as the EOL flow judges them, a map's
  // nodes, a diagnosis: pipeline/report.h, one home each.
  fit::FitData measured;
  std::optional<io::RecordingSet> set;
  if (auto set_dir = args->Get("set")) {
    auto read = io::ReadRecordingSet(*set_dir);
    if (!read.ok()) return Fail(std::string(read.status().message()));
    set = std::move(*read);
    ident::IdentifyOptions opt;
    opt.progress = ProgressLine("report: identifying point").Callback();
    if (auto st = pipeline::AddRecordingSetToReport(*set, *set_dir, opt, &measured, &in); !st.ok()) {
      return Fail(std::string(st.message()));
    }
    if (args->Has("diagnose")) {
      std::fprintf(stderr, "report: diagnosing %s\n", set_dir->c_str());
      if (auto st = pipeline::AddDiagnosisOfSetToReport(*set, *set_dir, &in); !st.ok()) {
        return Fail(*set_dir + ": --diagnose: " + std::string(st.message()));
      }
    }
  }
  if (auto map_path = args->Get("map")) {
    io::FluxMapReadOptions ro;
    ro.convention = *convention;
    auto map = io::ReadFluxMapCsv(*map_path, ro);
    if (!map.ok()) return Fail(std::string(map.status().message()));
    std::fprintf(stderr, "report: map %s: %s\n", map_path->c_str(), map->convention.Describe().c_str());
    pipeline::AddFluxMapToReport(*map, *map_path, &measured, &in);
  }
  if (auto d = args->Get("diagnosis")) {
    auto dj = ReadJson(*d);
    if (!dj.ok()) return Fail(std::string(dj.status().message()));
    pipeline::AddDiagnosisDocumentToReport(*dj, *d, &in);
  }
  std::fprintf(stderr, "report: building tables and figures for %s\n", cal->serial().c_str());
  auto rep = pipeline::BuildReportPage(in);
  if (!rep.ok()) return Fail(std::string(rep.status().message()));
  if (auto st = WriteNewOutput(*args, {"out", out}, rep->html); !st.ok()) return Fail(std::string(st.message()));
  PrintSummary({out, cal->serial(), in.verdict, io::Sha256Hex(rep->html), cal->version, rep->figures,
                rep->html.size(), rep->ellipse_speed_rpm},
               args->Has("json"));
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("report", "one self-contained HTML report page for a calibration", RunReport,
                         "fluxcal report calibration.json --out report.html [--force] [--set DIR] [--diagnosis FILE] [flags]\n"
                         "fluxcal report SERIAL --server ADDR [--version N] [--speed-rpm N] [--udc-v V] "
                         "--out report.html\n"
                         "fluxcal report SERIAL --server ADDR --set DIR [--diagnosis FILE] [flags]   (page built here)",
                         kReportFlags);

}  // namespace fluxcal::cli
