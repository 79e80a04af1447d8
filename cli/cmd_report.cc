// fluxcal report calibration.json [--set RECORDING_SET_DIR] [--diagnosis report.json]
//                [--speed-rpm N] [--udc-v V] --out report.html [--json]
// fluxcal report SERIAL --server ADDR [--version N] [...same flags]
// One self-contained static HTML page per calibration (report/report.h,
// docs/report.md). With --set the set is identified again so that the
// page shows the identified points against the fitted surfaces, the
// verdict is judged as the EOL flow judges it, and the manifest's DC-link
// voltage sets the voltage limit. With --server the stored calibration is
// fetched with what only the store knows: when it was created, its stored
// verdict and whether it is released for flashing.
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iostream>

#include "absl/strings/numbers.h"

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_remote.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "identification/identify.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "pipeline/pipeline.h"
#include "pipeline/points.h"
#include "report/report.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) {
  std::fprintf(stderr, "fluxcal report: %s\n", m.c_str());
  return code;
}

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

// The stored calibration of `serial` with the store's provenance merged
// into its JSON (created_utc, verdict, released), as the report reads it.
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
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(rec.calibration_json());
  } catch (const nlohmann::json::exception& e) {
    return absl::DataLossError("stored calibration of " + serial + " is not JSON: " + e.what());
  }
  j["version"] = rec.version();
  j["created_utc"] = rec.created_utc();
  j["verdict"] = rec.verdict();
  // The release flag comes with a table export; a caller without the
  // right to export unreleased versions learns nothing, and says so.
  v1::ExportTableRequest er;
  er.set_serial(serial);
  er.set_version(rec.version());
  er.set_table("mtpa");
  er.set_format("csv");
  v1::ExportTableResponse eresp;
  grpc::ClientContext ectx;
  ectx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  if (stub->ExportTable(&ectx, er, &eresp).ok()) {
    j["released"] = eresp.released() ? "released for flashing" : "not released";
  }
  return j;
}

// The service's fleet statistics at its default operating points.
absl::StatusOr<std::vector<report::FleetPoint>> FetchFleet(const std::string& server) {
  auto stub = MakeStub(server);
  if (!stub) return absl::InvalidArgumentError("--server " + server + ": cannot set up the client");
  v1::FleetStatisticsRequest req;
  v1::FleetStatisticsResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto s = stub->FleetStatistics(&ctx, req, &resp);
  if (!s.ok()) return absl::UnavailableError("FleetStatistics: " + s.error_message());
  std::vector<report::FleetPoint> out;
  for (const auto& p : resp.points()) {
    report::FleetPoint f;
    f.id_a = p.id_a(); f.iq_a = p.iq_a(); f.serials = p.serials();
    f.ldd_h_mean = p.ldd_h_mean(); f.ldd_h_std = p.ldd_h_std();
    f.lqq_h_mean = p.lqq_h_mean(); f.lqq_h_std = p.lqq_h_std();
    f.psi_d_wb_mean = p.psi_d_wb_mean(); f.psi_d_wb_std = p.psi_d_wb_std();
    f.torque_nm_mean = p.torque_nm_mean(); f.torque_nm_std = p.torque_nm_std();
    f.outliers.assign(p.outliers().begin(), p.outliers().end());
    out.push_back(std::move(f));
  }
  return out;
}

const FlagSpecs kReportFlags = {
    {"out", "FILE", "HTML page to write (required; - for stdout)"},
    {"server", "ADDR", "the positional argument is a SERIAL stored there, HOST[:PORT] (default port 50051)"},
    {"version", "N", "with --server: calibration version (default the latest)"},
    {"set", "DIR", "recording set: draws the identified points, judges the verdict, gives the DC-link voltage"},
    {"diagnosis", "FILE", "a `fluxcal diagnose --json` document to include"},
    {"speed-rpm", "RPM", "speed of the voltage-limit curve, mechanical rpm (default 1.5 x base speed)"},
    {"udc-v", "V", "DC-link voltage, V (default the set's manifest drive.udc_v, else 50 as export)"},
    {"json", "", "print a summary (verdict, figures, bytes) as one JSON document"},
};

int RunReport(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kReportFlags);
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  if (auto e = CheckOutToStdout(*args); !e.empty()) return Fail(e, 2);
  if (args->positional.size() != 1 || !args->Get("out")) {
    return Fail("usage: fluxcal report calibration.json|SERIAL --server ADDR [--version N] [--set RECORDING_SET_DIR] "
                "[--diagnosis report.json] [--speed-rpm N] [--udc-v V] --out report.html [--json]", 2);
  }
  const std::string cal_path = args->positional[0];
  absl::StatusOr<nlohmann::json> cal_json;
  report::ReportInputs in;
  if (auto server = args->Get("server")) {
    int version = 0;
    if (auto v = args->Get("version"); v && (!absl::SimpleAtoi(*v, &version) || version < 0)) {
      return Fail("flag --version: expected a non-negative integer", 2);
    }
    cal_json = FetchCalibration(*server, cal_path, version);
    in.calibration_path = cal_path + " from the service at " + *server;
    if (auto fleet = FetchFleet(*server); fleet.ok()) {
      in.fleet = std::move(*fleet);
      in.fleet_source = "FleetStatistics of the service at " + *server + " (latest calibration of every serial)";
    } else {
      std::fprintf(stderr, "fluxcal report: no fleet comparison: %s\n", std::string(fleet.status().message()).c_str());
    }
    in.calibration_file_mtime_utc = "unknown";
  } else {
    if (args->Get("version")) return Fail("flag --version needs --server", 2);
    cal_json = ReadJson(cal_path);
    in.calibration_path = cal_path;
    in.calibration_file_mtime_utc = FileMtimeUtc(cal_path);
  }
  if (!cal_json.ok()) return Fail(std::string(cal_json.status().message()));
  auto cal = fit::Calibration::FromJson(*cal_json);
  if (!cal.ok()) return Fail(in.calibration_path + ": " + std::string(cal.status().message()));

  in.calibration = &*cal;
  in.calibration_json = *cal_json;
  in.software_version = FLUXCAL_VERSION;
  for (auto [flag, dst] : {std::pair<const char*, double*>{"speed-rpm", &in.ellipse_speed_rpm}}) {
    auto v = args->GetDouble(flag);
    if (!v.ok()) return Fail(std::string(v.status().message()), 2);
    if (v->has_value()) {
      if (!(**v > 0)) return Fail(std::string("flag --") + flag + ": must be positive", 2);
      *dst = **v;
    }
  }
  auto udc = args->GetDouble("udc-v");
  if (!udc.ok()) return Fail(std::string(udc.status().message()), 2);
  if (udc->has_value()) {
    if (!(**udc > 0)) return Fail("flag --udc-v: must be positive", 2);
    in.udc_v = **udc;
    in.udc_source = "--udc-v";
  }

  // Verdict: as the EOL flow judges it when the set is here (nominal
  // psi_pm, unreliable points); otherwise from the fit alone.
  fit::FitData identified;
  pipeline::FitTolerances tol;
  if (auto set_dir = args->Get("set")) {
    auto set = io::ReadRecordingSet(*set_dir);
    if (!set.ok()) return Fail(std::string(set.status().message()));
    if (!set->manifest.serial.empty() && set->manifest.serial != cal->serial()) {
      return Fail(*set_dir + "/manifest.json: field 'serial': '" + set->manifest.serial +
                  "' is not the calibration's serial '" + cal->serial() + "'");
    }
    ident::IdentifyOptions opt;
    opt.progress = [](size_t k, size_t n) {
      std::fprintf(stderr, "\rreport: identifying point %zu/%zu", k + 1, n);
      if (k + 1 == n) std::fprintf(stderr, "\n");
    };
    auto ids = pipeline::IdentifySet(*set, opt);
    if (!ids.ok()) return Fail(std::string(ids.status().message()));
    size_t unreliable = 0;
    for (const auto& p : ids->points) {
      if (!p.reliable) ++unreliable;
      identified.inductances.push_back(pipeline::ToObservation(p));
    }
    // A set may carry the bench's own identification (hf_results.csv)
    // instead of, or besides, waveforms; its points are drawn the same way.
    if (!set->hf_results.empty()) {
      const auto hf = fit::FitDataFromHfRows(&set->manifest, set->hf_results);
      identified.inductances.insert(identified.inductances.end(), hf.inductances.begin(), hf.inductances.end());
    }
    in.identified = &identified;
    in.set_path = *set_dir;
    if (!in.udc_v && set->manifest.drive.udc_v) {
      in.udc_v = *set->manifest.drive.udc_v;
      in.udc_source = *set_dir + "/manifest.json drive.udc_v";
    }
    const double nominal = set->manifest.motor.psi_pm_wb.value_or(0.0);
    in.verdict = pipeline::Verdict(*cal, nominal, identified.inductances.size(), unreliable, tol);
    in.verdict_basis = "judged as the EOL flow does: fit, psi_pm against the manifest's nominal, point flags";
  } else if (cal_json->contains("verdict") && (*cal_json)["verdict"].is_string()) {
    in.verdict = (*cal_json)["verdict"].get<std::string>();
    in.verdict_basis = "as stored with the calibration";
  } else {
    in.verdict = pipeline::Verdict(*cal, 0.0, 0, 0, tol);
    in.verdict_basis = "from the fit alone; give --set to also check psi_pm against nominal and the point flags";
  }
  if (auto d = args->Get("diagnosis")) {
    auto dj = ReadJson(*d);
    if (!dj.ok()) return Fail(std::string(dj.status().message()));
    in.diagnosis = *dj;
    in.diagnosis_path = *d;
  }
  std::fprintf(stderr, "report: building tables and figures for %s\n", cal->serial().c_str());
  auto rep = report::BuildReport(in);
  if (!rep.ok()) return Fail(std::string(rep.status().message()));
  const std::string out = *args->Get("out");
  if (auto st = WriteOutput(out, rep->html); !st.ok()) return Fail(std::string(st.message()));
  if (args->Has("json")) {
    std::cout << nlohmann::json{{"out", out}, {"serial", cal->serial()}, {"version", cal->version},
                                {"verdict", in.verdict}, {"figures", rep->figures}, {"bytes", rep->html.size()},
                                {"voltage_limit_speed_rpm", rep->ellipse_speed_rpm}}
                     .dump(2, ' ', false, nlohmann::json::error_handler_t::replace)
              << "\n";
  } else {
    std::fprintf(out == "-" ? stderr : stdout, "%s: report for %s v%d (%s), %d figures, %zu bytes\n", out.c_str(), cal->serial().c_str(),
                cal->version, in.verdict.c_str(), rep->figures, rep->html.size());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("report", "one self-contained HTML report page for a calibration", RunReport,
                         "fluxcal report calibration.json --out report.html [--set DIR] [--diagnosis FILE] [flags]\n"
                         "fluxcal report SERIAL --server ADDR [--version N] --out report.html [--set DIR] [flags]",
                         kReportFlags);

}  // namespace fluxcal::cli
