// fluxcal eol <recording-set> --server ADDR [--station ID] [--model M]
//             [--tables-dir DIR] [--upload-recording] [--json]
// The EOL station flow: identify every point locally, stream the results
// for the serial, (with --upload-recording) upload the raw set, ask for a
// fit and its verdict, fetch the ECU tables. Each stream declares its end
// (count and SHA-256 of what it carries), and the reply's count and digest
// of what the service stored must equal what was sent, or eol stops (exit
// 1) before anything is fitted.
#include <chrono>
#include <thread>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>

#include <grpcpp/grpcpp.h>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_remote.h"
#include "io/sha256.h"
#include "pipeline/ingest_stream.h"
#include "pipeline/points.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
namespace {

// The files of a set as IngestRecording wants them: manifest.json and
// every file the manifest names (the service refuses any other), under
// normalised relative names, with the bytes as on disk.
absl::StatusOr<io::RecordingFiles> SetFiles(const std::string& dir, const io::Manifest& m) {
  auto norm = [](const std::string& f) { return std::filesystem::path(f).lexically_normal().generic_string(); };
  std::vector<std::string> names = {"manifest.json"};
  for (const auto& p : m.points) names.push_back(norm(p.file));
  if (m.steady_state) names.push_back(norm(*m.steady_state));
  if (m.hf_results) names.push_back(norm(*m.hf_results));
  io::RecordingFiles files;
  for (const auto& name : names) {
    if (files.count(name)) continue;
    auto data = io::ReadFileToString((std::filesystem::path(dir) / name).string());
    if (!data.ok()) return data.status();
    files.emplace(name, std::move(*data));
  }
  return files;
}

// UNAVAILABLE and DEADLINE_EXCEEDED may hide a reply that was lost after
// the server stored the run: `attempt` is repeated (3 tries in all) with
// the same idempotency key, so the retry stores nothing twice.
template <class F>
grpc::Status WithRetries(const std::string& serial, const char* what, F attempt) {
  grpc::Status s;
  for (int k = 0; k < 3; ++k) {
    if (k > 0) {
      std::fprintf(stderr, "eol %s: %s: %s; retrying the same %s\n", serial.c_str(), what, s.error_message().c_str(),
                   what);
      std::this_thread::sleep_for(std::chrono::milliseconds(500 << k));
    }
    s = attempt();
    if (s.error_code() != grpc::StatusCode::UNAVAILABLE && s.error_code() != grpc::StatusCode::DEADLINE_EXCEEDED) {
      break;
    }
  }
  return s;
}

const FlagSpecs kEolFlags = {
    {"server", "ADDR", "the service, HOST[:PORT] (default port 50051; required)"},
    {"station", "ID", "station id recorded with the run (default eol)"},
    {"model", "M", "model family the service fits, as `fluxcal fit --model` (default auto)"},
    {"tables-dir", "DIR", "on a pass, fetch the MTPA (CDFX) and field-weakening (DCM) tables there"},
    {"upload-recording", "", "also upload the raw waveforms (replayable on the service)"},
    {"json", "", "print the result as one JSON document"},
    {kForceFlag.name, kForceFlag.value, "replace table files in --tables-dir that exist (refused otherwise)"},
};

int RunEol(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kEolFlags);
  if (!args.ok() || args->positional.size() != 1 || !args->Get("server")) {
    std::fprintf(stderr, "usage: fluxcal eol <recording-set> --server ADDR [--station ID] [--model M] "
                         "[--tables-dir DIR [--force]] [--upload-recording] [--json]\n");
    return 2;
  }
  auto set = io::ReadRecordingSet(args->positional[0]);
  if (!set.ok()) {
    std::fprintf(stderr, "fluxcal eol: %s\n", std::string(set.status().message()).c_str());
    return 1;
  }
  const std::string serial = set->manifest.serial;
  std::fprintf(stderr, "eol %s: identifying %zu points\n", serial.c_str(), set->waveforms.size());
  auto ids = pipeline::IdentifySet(*set);
  if (!ids.ok()) {
    std::fprintf(stderr, "fluxcal eol: %s\n", std::string(ids.status().message()).c_str());
    return 1;
  }
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  // Stream the per-point results (one message per point, as a station does
  // while the motor is on the bench).
  v1::IngestHfResultsResponse ing;
  const pipeline::StreamTotals points_sent{0, static_cast<int64_t>(ids->points.size()), 0,
                                           pipeline::HfPointsSha256(ids->points)};
  {
    for (const auto& f : ids->failures) std::fprintf(stderr, "eol %s: point not identified: %s\n", serial.c_str(), f.c_str());
    std::vector<v1::IngestHfResultsRequest> msgs;
    std::string content;
    for (const auto& r : ids->points) {
      v1::IngestHfResultsRequest m;
      *m.add_points() = pipeline::ToProto(r);
      m.AppendToString(&content);
      msgs.push_back(std::move(m));
    }
    if (msgs.empty()) msgs.emplace_back();
    auto& first = msgs.front();
    first.set_serial(serial);
    first.set_station_id(args->Get("station").value_or("eol"));
    // The stream declares its end: the service refuses it whole when a
    // message is lost, cut or fails to parse (docs/service.md).
    first.set_end_follows(true);
    auto* mo = first.mutable_motor();
    mo->set_pole_pairs(set->manifest.motor.pole_pairs);
    mo->set_rs_ohm(set->manifest.motor.rs_ohm.value_or(0));
    mo->set_psi_pm_wb(set->manifest.motor.psi_pm_wb.value_or(0));
    // The run's idempotency key is its content: a retry after a lost reply
    // (UNAVAILABLE, DEADLINE_EXCEEDED) stores nothing twice.
    first.set_idempotency_key("eol-" + io::Sha256Hex(content).substr(0, 40));
    {
      v1::IngestHfResultsRequest last;
      last.mutable_end()->set_messages(static_cast<int64_t>(msgs.size()) + 1);
      last.mutable_end()->set_count(static_cast<int64_t>(ids->points.size()));
      last.mutable_end()->set_sha256(points_sent.sha256);
      msgs.push_back(std::move(last));
    }
    const grpc::Status s = WithRetries(serial, "run", [&] {
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
      auto writer = stub->IngestHfResults(&ctx, &ing);
      // One message per point, as a station does while the motor is on the bench.
      for (const auto& m : msgs) {
        if (!writer->Write(m)) break;
      }
      writer->WritesDone();
      return writer->Finish();
    });
    if (!s.ok()) return ReportRpcError("eol", s);
  }
  // What the service stored must be what this station sent: count and digest.
  if (auto st = pipeline::CheckStored(points_sent, {0, ing.accepted(), 0, ing.points_sha256()}, "points");
      !st.ok()) {
    std::fprintf(stderr, "fluxcal eol: %s: run %lld: %s\n", serial.c_str(), static_cast<long long>(ing.run_id()),
                 std::string(st.message()).c_str());
    return 1;
  }
  std::fprintf(stderr, "eol %s: %d points stored (run %lld, sha256 %s, as sent)\n", serial.c_str(), ing.accepted(),
               static_cast<long long>(ing.run_id()), ing.points_sha256().substr(0, 16).c_str());
  // The raw set, so that the service can diagnose this serial (Diagnose
  // reads the latest stored recording) and fit it from everything the set
  // holds, as `fluxcal fit SET` does. Uploaded before the fit: a failed
  // upload leaves no calibration version behind, and rerunning the command
  // replays both ingests by their keys instead of storing them twice.
  std::optional<v1::IngestRecordingResponse> rec;
  if (args->Has("upload-recording")) {
    auto files = SetFiles(args->positional[0], set->manifest);
    if (!files.ok()) {
      std::fprintf(stderr, "fluxcal eol: %s\n", std::string(files.status().message()).c_str());
      return 1;
    }
    std::string content;
    for (const auto& [name, data] : *files) content += name + '\n' + std::to_string(data.size()) + '\n' + data;
    const std::string key = "eolrec-" + io::Sha256Hex(content).substr(0, 40);
    const pipeline::StreamTotals files_sent{0, static_cast<int64_t>(files->size()), pipeline::RecordingFilesBytes(*files),
                                            pipeline::RecordingFilesSha256(*files)};
    std::fprintf(stderr, "eol %s: uploading the recording (%zu files, %zu bytes)\n", serial.c_str(), files->size(),
                 content.size());
    rec.emplace();
    const grpc::Status s = WithRetries(serial, "recording upload", [&] {
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(300));
      auto writer = stub->IngestRecording(&ctx, &*rec);
      // Chunks well under the service's message limit; the first names the
      // serial, the station and the key.
      constexpr size_t kChunk = 1 << 20;
      bool first = true, open = true;
      int64_t chunks = 0;
      for (auto it = files->begin(); open && it != files->end(); ++it) {
        const auto& [name, data] = *it;
        // An empty file still goes out as one chunk, so the set is complete.
        for (size_t off = 0; open && (off == 0 || off < data.size()); off += kChunk) {
          v1::RecordingChunk c;
          if (first) {
            c.set_serial(serial);
            c.set_station_id(args->Get("station").value_or("eol"));
            c.set_idempotency_key(key);
            c.set_end_follows(true);
            first = false;
          }
          c.set_path(name);
          c.set_data(data.substr(off, kChunk));
          open = writer->Write(c);   // false: the stream broke; Finish says why
          ++chunks;
        }
      }
      if (open) {
        // The declared end: what was sent, checked by the service before
        // anything is stored.
        v1::RecordingChunk last;
        last.mutable_end()->set_messages(chunks + 1);
        last.mutable_end()->set_count(files_sent.count);
        last.mutable_end()->set_bytes(files_sent.bytes);
        last.mutable_end()->set_sha256(files_sent.sha256);
        writer->Write(last);
      }
      writer->WritesDone();
      return writer->Finish();
    });
    if (!s.ok()) return ReportRpcError("eol", s);
    if (auto st = pipeline::CheckStored(files_sent, {0, rec->files(), rec->files_bytes(), rec->files_sha256()}, "files");
        !st.ok()) {
      std::fprintf(stderr, "fluxcal eol: %s: recording run %lld: %s\n", serial.c_str(),
                   static_cast<long long>(rec->run_id()), std::string(st.message()).c_str());
      return 1;
    }
    std::fprintf(stderr, "eol %s: recording %s stored (run %lld, %d points%s)\n", serial.c_str(),
                 rec->recording_sha256().substr(0, 16).c_str(), static_cast<long long>(rec->run_id()), rec->points(),
                 rec->replayed() ? ", replayed" : "");
  }
  std::fprintf(stderr, "eol %s: fitting\n", serial.c_str());
  v1::FitRequest fr;
  fr.set_serial(serial);
  fr.set_model(args->Get("model").value_or("auto"));
  v1::FitResponse fit;
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    auto s = stub->Fit(&ctx, fr, &fit);
    if (!s.ok()) return ReportRpcError("eol", s);
  }
  nlohmann::json out = {{"serial", serial}, {"run_id", ing.run_id()}, {"accepted", ing.accepted()},
                        {"rejected", ing.rejects_size()} /* always 0: a bad point fails the stream */,
                        {"points_sha256", ing.points_sha256()}, {"version", fit.calibration().version()},
                        {"model", fit.calibration().model()}, {"verdict", fit.calibration().verdict()},
                        {"pass", fit.pass()}, {"psi_pm_wb", fit.calibration().psi_pm_wb()},
                        {"rms_relative", fit.calibration().rms_relative()}, {"tables", nlohmann::json::array()}};
  if (rec) {
    out["recording"] = {{"run_id", rec->run_id()}, {"points", rec->points()}, {"sha256", rec->recording_sha256()},
                        {"bytes", rec->recording_bytes()}, {"replayed", rec->replayed()}, {"files", rec->files()},
                        {"files_sha256", rec->files_sha256()}};
  }
  if (auto dir = args->Get("tables-dir"); dir && fit.pass()) {
    std::filesystem::create_directories(*dir);
    for (auto [table, format] : {std::pair<const char*, const char*>{"mtpa", "cdfx"}, {"fw", "dcm"}}) {
      v1::ExportTableRequest er;
      er.set_serial(serial);
      er.set_version(fit.calibration().version());
      er.set_table(table);
      er.set_format(format);
      // The drive's Udc as the set states it (a run of HF results does not
      // carry it into the store); without one the service asks for it.
      if (set->manifest.drive.udc_v) er.set_udc_v(*set->manifest.drive.udc_v);
      v1::ExportTableResponse resp;
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
      auto s = stub->ExportTable(&ctx, er, &resp);
      if (!s.ok()) return ReportRpcError("eol", s);
      const std::string path = *dir + "/" + serial + "_v" + std::to_string(resp.version()) + "_" + table + "." + format;
      // Named by serial and stored version, which a store never reuses: a
      // file already there came from another store (the overwrite rule,
      // cli/args.h, applies when the names are known, i.e. here).
      if (auto st = WriteNewOutput(*args, {"tables-dir", path}, resp.data()); !st.ok()) {
        std::fprintf(stderr, "fluxcal eol: %s\n", std::string(st.message()).c_str());
        return 1;
      }
      // sha256 of the file written (= sha256sum); crc32/sha256 of the reply are over the values.
      out["tables"].push_back({{"path", path}, {"sha256", io::Sha256Hex(resp.data())},
                               {"payload_crc32", resp.crc32()}, {"payload_sha256", resp.sha256()}});
    }
  }
  if (args->Has("json")) {
    std::cout << out.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  } else {
    std::printf("%s: calibration v%d (%s), verdict %s, psi_pm %.5g Wb, fit rms %.3f %%\n", serial.c_str(),
                fit.calibration().version(), fit.calibration().model().c_str(), fit.calibration().verdict().c_str(),
                fit.calibration().psi_pm_wb(), 100 * fit.calibration().rms_relative());
    for (const auto& t : out["tables"]) std::printf("  %s payload_crc32 %s\n", t["path"].get<std::string>().c_str(), t["payload_crc32"].get<std::string>().c_str());
  }
  return fit.pass() ? 0 : 3;
}

const FlagSpecs kListFlags = {
    {"server", "ADDR", "the service, HOST[:PORT] (default port 50051; required)"},
    {"prefix", "P", "only serials starting with P"},
    {"failed", "", "only motors whose latest verdict is a fail"},
    {"page-size", "N", "accepted for compatibility; has no effect (all pages are fetched)"},
    {"json", "", "print the result as one JSON document"},
};

int RunList(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kListFlags);
  if (!args.ok() || !args->Get("server")) {
    std::fprintf(stderr, "usage: fluxcal list --server ADDR [--prefix P] [--failed] [--json]\n");
    return 2;
  }
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
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    auto s = stub->ListMotors(&ctx, req, &resp);
    if (!s.ok()) return ReportRpcError("list", s);
    for (const auto& m : resp.motors()) {
      all.push_back({{"serial", m.serial()}, {"latest_version", m.latest_version()}, {"verdict", m.verdict()},
                     {"runs", m.runs()}, {"updated_utc", m.updated_utc()}});
    }
    token = resp.next_page_token();
  } while (!token.empty());
  if (args->Has("json")) {
    std::cout << nlohmann::json{{"motors", all}}.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  } else {
    std::printf("%-24s %7s %5s  %-20s %s\n", "serial", "version", "runs", "updated", "verdict");
    for (const auto& m : all) {
      std::printf("%-24s %7d %5d  %-20s %s\n", m["serial"].get<std::string>().c_str(), m["latest_version"].get<int>(),
                  m["runs"].get<int>(), m["updated_utc"].get<std::string>().c_str(), m["verdict"].get<std::string>().c_str());
    }
  }
  return 0;
}

const FlagSpecs kHistoryFlags = {
    {"server", "ADDR", "the service, HOST[:PORT] (default port 50051; required)"},
    {"json", "", "print the result as one JSON document"},
};

int RunHistory(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kHistoryFlags);
  if (!args.ok() || args->positional.size() != 1 || !args->Get("server")) {
    std::fprintf(stderr, "usage: fluxcal history SERIAL --server ADDR [--json]\n");
    return 2;
  }
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  v1::HistoryRequest req;
  req.set_serial(args->positional[0]);
  v1::HistoryResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto s = stub->History(&ctx, req, &resp);
  if (!s.ok()) return ReportRpcError("history", s);
  nlohmann::json ev = nlohmann::json::array();
  for (const auto& e : resp.events()) {
    ev.push_back({{"created_utc", e.created_utc()}, {"kind", e.kind()}, {"run_id", e.run_id()},
                  {"version", e.version()}, {"detail", e.detail()}});
  }
  if (args->Has("json")) {
    std::cout << nlohmann::json{{"serial", resp.serial()}, {"events", ev}}.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  } else {
    for (const auto& e : ev) {
      std::printf("%s  %-12s run %-5lld v%-3d %s\n", e["created_utc"].get<std::string>().c_str(),
                  e["kind"].get<std::string>().c_str(), static_cast<long long>(e["run_id"].get<int64_t>()),
                  e["version"].get<int>(), e["detail"].get<std::string>().c_str());
    }
  }
  return 0;
}

const FlagSpecs kFleetFlags = {
    {"server", "ADDR", "the service, HOST[:PORT] (default port 50051; required)"},
    {"json", "", "print the result as one JSON document"},
};

int RunFleet(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kFleetFlags);
  if (!args.ok() || !args->Get("server")) {
    std::fprintf(stderr, "usage: fluxcal fleet --server ADDR [--json]\n");
    return 2;
  }
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  v1::FleetStatisticsRequest req;
  v1::FleetStatisticsResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  auto s = stub->FleetStatistics(&ctx, req, &resp);
  if (!s.ok()) return ReportRpcError("fleet", s);
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
    std::cout << nlohmann::json{{"points", pts}}.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
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
FLUXCAL_REGISTER_COMMAND("list", "list motors known to the service", RunList,
                         "fluxcal list --server ADDR [--prefix P] [--failed] [--json]",
                         kListFlags);
FLUXCAL_REGISTER_COMMAND("history", "a serial's runs and calibration versions", RunHistory,
                         "fluxcal history SERIAL --server ADDR [--json]",
                         kHistoryFlags);
FLUXCAL_REGISTER_COMMAND("fleet", "fleet statistics per operating point, outlier serials", RunFleet,
                         "fluxcal fleet --server ADDR [--json]",
                         kFleetFlags);

}  // namespace fluxcal::cli
