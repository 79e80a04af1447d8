#include "cli/support_remote.h"

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "absl/strings/numbers.h"
#include "absl/strings/str_replace.h"
#include "cli/args.h"
#include "cli/support_output.h"
#include "io/csv.h"
#include "io/net.h"
#include "nlohmann/json.hpp"
#include "io/sha256.h"
#include "pipeline/export.h"
#include "server/bearer.h"

namespace fluxcal::cli {

ClientOptions& GlobalClientOptions() {
  static ClientOptions o = [] {
    ClientOptions d;
    auto env = [](const char* n) { const char* v = std::getenv(n); return v ? std::string(v) : std::string(); };
    d.ca_file = env("FLUXCAL_CA");
    d.cert_file = env("FLUXCAL_CERT");
    d.key_file = env("FLUXCAL_KEY");
    d.token_file = env("FLUXCAL_TOKEN_FILE");
    return d;
  }();
  return o;
}

std::string TakeClientFlags(std::vector<std::string>* args) {
  ClientOptions& o = GlobalClientOptions();
  const std::map<std::string, std::string*> value_flags = {
      {"--ca", &o.ca_file}, {"--cert", &o.cert_file}, {"--key", &o.key_file}, {"--token-file", &o.token_file}};
  std::vector<std::string> rest;
  for (size_t k = 0; k < args->size(); ++k) {
    const std::string& a = (*args)[k];
    if (a == "--insecure") {
      o.insecure = true;
      continue;
    }
    const auto eq = a.find('=');
    const std::string name = a.substr(0, eq);
    auto it = value_flags.find(name);
    if (it == value_flags.end()) {
      rest.push_back(a);
      continue;
    }
    if (eq != std::string::npos) {
      *it->second = a.substr(eq + 1);
    } else if (k + 1 < args->size()) {
      *it->second = (*args)[++k];
    } else {
      return name + " needs a value";
    }
  }
  *args = std::move(rest);
  return "";
}

namespace {

// The target of the last MakeStub, for the error hints.
std::string& LastTarget() {
  static std::string target;
  return target;
}

bool ReadPem(const std::string& path, const char* what, std::string* out) {
  if (path.empty()) return true;
  auto text = io::ReadFileToString(path);
  if (!text.ok()) {
    std::fprintf(stderr, "fluxcal: %s: cannot read %s\n", path.c_str(), what);
    return false;
  }
  *out = std::move(*text);
  return true;
}

}  // namespace

std::unique_ptr<v1::CalibrationService::Stub> MakeStub(const std::string& server) {
  const std::string address = ServerTarget(server);
  LastTarget() = address;
  const ClientOptions& o = GlobalClientOptions();
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  std::shared_ptr<grpc::ChannelCredentials> creds;
  // Loopback by what the name resolves to, every address of it (io/net.h):
  // a name spelt like 127.x but resolving elsewhere gets TLS.
  const io::LoopbackCheck where = io::CheckLoopback(address);
  const bool tls = !o.ca_file.empty() || !o.cert_file.empty() || (!o.insecure && !where.loopback);
  // A bearer token is a password: never in clear off this machine, not even
  // with --insecure.
  if (!tls && !where.loopback && !o.token_file.empty()) {
    std::fprintf(stderr,
                 "fluxcal: --token-file: tokens need TLS off loopback; %s %s, so the token is not sent in "
                 "plaintext (drop --insecure and pass --ca)\n",
                 address.c_str(), where.why.c_str());
    return nullptr;
  }
  if (tls) {
    grpc::SslCredentialsOptions ssl;
    if (!ReadPem(o.ca_file, "--ca", &ssl.pem_root_certs) || !ReadPem(o.cert_file, "--cert", &ssl.pem_cert_chain) ||
        !ReadPem(o.key_file, "--key", &ssl.pem_private_key)) {
      return nullptr;
    }
    creds = grpc::SslCredentials(ssl);
  } else {
    creds = grpc::InsecureChannelCredentials();
  }
  std::optional<std::string> token;
  if (!o.token_file.empty()) {
    auto text = io::ReadFileToString(o.token_file);
    if (!text.ok()) {
      std::fprintf(stderr, "fluxcal: %s: cannot read --token-file\n", o.token_file.c_str());
      return nullptr;
    }
    token = text->substr(0, text->find_first_of("\r\n"));
  }
  return v1::CalibrationService::NewStub(server::BearerChannel(address, creds, token, args));
}

int ReportRpcError(const char* cmd, const grpc::Status& s) {
  static const char* kNames[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED",
                                 "NOT_FOUND", "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED",
                                 "FAILED_PRECONDITION", "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED",
                                 "INTERNAL", "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  const int c = static_cast<int>(s.error_code());
  const std::string& target = LastTarget();
  const std::string& msg = s.error_message();
  auto contains = [&](const char* what) {
    std::string lower = msg;
    for (auto& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    return lower.find(what) != std::string::npos;
  };
  // A hint for the codes a setup mistake gives ($target and $why filled in).
  static const std::map<grpc::StatusCode, std::string> kHints = {
      {grpc::StatusCode::DEADLINE_EXCEEDED,
       "$target did not answer in time: is the address right (a firewall drops, not refuses)? "
       "a server under load or a long fit may need a retry"},
      {grpc::StatusCode::UNAUTHENTICATED,
       "$target wants credentials: give --token-file FILE (made by `fluxcal admin add-key`) or a "
       "client certificate (--cert, --key) it accepts"},
      {grpc::StatusCode::PERMISSION_DENIED,
       "the identity of your token/certificate lacks the role for this call on $target: "
       "see `fluxcal admin list-keys` on the server side"},
  };
  std::string hint, why;
  if (s.error_code() == grpc::StatusCode::UNAVAILABLE) {
    why = contains("connection refused")                                ? "connection refused"
          : contains("handshake") || contains("ssl") || contains("tls") ? "TLS handshake failed"
          : contains("dns") || contains("resolve")                      ? "name not resolved"
                                                                         : "unavailable";
    hint = why == "name not resolved"
               ? "cannot reach $target ($why): check the host name given to --server"
               : "cannot reach $target ($why): is `fluxcal serve` running there? TLS: pass --ca (its CA; "
                 "--cert and --key if it requires client certificates), or --insecure for a plaintext test server "
                 "off loopback";
  } else if (auto it = kHints.find(s.error_code()); it != kHints.end()) {
    hint = it->second;
  }
  if (!hint.empty()) {
    std::fprintf(stderr, "fluxcal %s: %s\n", cmd,
                 absl::StrReplaceAll(hint, {{"$target", target}, {"$why", why}}).c_str());
  }
  std::fprintf(stderr, "fluxcal %s: %s: %s\n", cmd, c >= 0 && c <= 16 ? kNames[c] : "ERROR", msg.c_str());
  return 1;
}

int RunRemoteQuery(const std::vector<std::string>& argv, const FlagSpecs& flags) {
  auto args = ParseArgs(argv, flags);
  if (!args.ok()) std::fprintf(stderr, "fluxcal query: %s\n", std::string(args.status().message()).c_str());
  if (!args.ok() || args->positional.size() != 1) return UsageError(kRemoteQueryUsage);
  auto id = args->GetDouble("id-a");
  auto iq = args->GetDouble("iq-a");
  if (!id.ok() || !iq.ok() || !id->has_value() || !iq->has_value()) {
    std::fprintf(stderr, "fluxcal query: need --id-a and --iq-a\n");
    return 2;
  }
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  v1::QueryFluxRequest req;
  req.set_serial(args->positional[0]);
  int version = 0;
  if (auto v = args->Get("version"); v && !absl::SimpleAtoi(*v, &version)) return 2;
  req.set_version(version);
  auto* p = req.add_points();
  p->set_id_a(**id);
  p->set_iq_a(**iq);
  v1::QueryFluxResponse resp;
  if (auto s = CallWithDeadline(*stub, &v1::CalibrationService::Stub::QueryFlux, req, &resp); !s.ok()) {
    return ReportRpcError("query", s);
  }
  const auto& v = resp.values(0);
  if (args->Has("json")) {
    PrintJson({{"serial", resp.serial()}, {"version", resp.version()}, {"id_a", v.id_a()},
               {"iq_a", v.iq_a()}, {"psi_d_wb", v.psi_d_wb()}, {"psi_q_wb", v.psi_q_wb()},
               {"ldd_h", v.ldd_h()}, {"lqq_h", v.lqq_h()}, {"ldq_h", v.ldq_h()},
               {"ld_app_h", v.ld_app_h()}, {"lq_app_h", v.lq_app_h()}, {"torque_nm", v.torque_nm()},
               {"psi_d_wb_std", v.psi_d_wb_std()}, {"ldd_h_std", v.ldd_h_std()},
               {"lqq_h_std", v.lqq_h_std()}, {"torque_nm_std", v.torque_nm_std()},
               {"extrapolated", v.extrapolated()},
               {"region", v.region().empty() ? (v.extrapolated() ? "extrapolated" : "measured") : v.region()},
               {"valid", !v.invalid()}, {"invalid_reason", v.invalid_reason()}});
  } else {
    std::printf("serial %s v%d at id = %g A, iq = %g A: psi_d %.6g Wb, psi_q %.6g Wb, Ldd %.5g mH, Lqq %.5g mH, "
                "Ldq %.4g mH, torque %.4g N m%s\n",
                resp.serial().c_str(), resp.version(), v.id_a(), v.iq_a(), v.psi_d_wb(), v.psi_q_wb(),
                v.ldd_h() * 1e3, v.lqq_h() * 1e3, v.ldq_h() * 1e3, v.torque_nm(),
                v.extrapolated() ? " (extrapolated)" : v.region() == "by_symmetry" ? " (by symmetry)" : "");
    if (v.invalid()) std::printf("  NOT VALID: %s (differential inductance not positive definite)\n", v.invalid_reason().c_str());
  }
  return 0;
}

namespace {

// --udc-axis-v with --server: the reply's one table per Udc, each written
// as the local axis writes it (pipeline::UdcAxisPath), its signature beside
// it when the service signed (a stale one removed otherwise).
int WriteRemoteUdcAxis(const ParsedArgs& args, const v1::ExportTableRequest& req, const v1::ExportTableResponse& resp,
                       const std::vector<double>& udcs) {
  const std::string out = *args.Get("out");
  if (resp.udc_tables_size() != static_cast<int>(udcs.size())) {
    std::fprintf(stderr, "fluxcal export: the service sent %d tables for %zu voltages; nothing written\n",
                 resp.udc_tables_size(), udcs.size());
    return 1;
  }
  for (size_t k = 0; k < udcs.size(); ++k) {
    if (resp.udc_tables(static_cast<int>(k)).udc_v() != udcs[k]) {
      std::fprintf(stderr, "fluxcal export: the service's table %zu is at %g V, not the %g V asked; nothing written\n",
                   k + 1, resp.udc_tables(static_cast<int>(k)).udc_v(), udcs[k]);
      return 1;
    }
  }
  nlohmann::json files = nlohmann::json::array();
  for (size_t k = 0; k < udcs.size(); ++k) {
    const v1::ExportedUdcTable& t = resp.udc_tables(static_cast<int>(k));
    const std::string path = pipeline::UdcAxisPath(out, udcs[k]);
    if (auto st = WriteNewOutput(args, {"out", path}, t.data()); !st.ok()) {
      std::fprintf(stderr, "fluxcal export: %s\n", std::string(st.message()).c_str());
      return 1;
    }
    std::string sig_path;
    if (t.signature().empty()) {
      std::error_code ec;
      std::filesystem::remove(path + ".sig", ec);
    } else {
      sig_path = path + ".sig";
      if (auto st = WriteNewOutput(args, {"out", sig_path}, t.signature()); !st.ok()) {
        std::fprintf(stderr, "fluxcal export: %s\n", std::string(st.message()).c_str());
        return 1;
      }
    }
    if (t.clamped_cells() > 0) {
      std::fprintf(stderr, "fluxcal export: warning: Udc %g V: %d of %d cells clamped (requests beyond the limits)\n",
                   t.udc_v(), t.clamped_cells(), t.cells());
    }
    const std::string file_sha256 = io::Sha256Hex(t.data());
    files.push_back({{"out", path}, {"udc_v", t.udc_v()}, {"label_tag", t.label_tag()}, {"cells", t.cells()},
                     {"clamped_cells", t.clamped_cells()}, {"sha256", file_sha256}, {"payload_crc32", t.crc32()},
                     {"payload_sha256", t.sha256()}, {"bytes", t.data().size()}, {"signature", sig_path}});
    if (!args.Has("json")) {
      std::printf("%s: %s v%d %s table (%s) at Udc %g V (labels tagged %s), verdict %s, %s\n  sha256 %s (file)\n"
                  "  payload_crc32 %s payload_sha256 %s (values)\n",
                  path.c_str(), resp.serial().c_str(), resp.version(), req.table().c_str(), req.format().c_str(),
                  t.udc_v(), t.label_tag().c_str(), resp.verdict().c_str(),
                  resp.released() ? "released" : "not released", file_sha256.c_str(), t.crc32().c_str(),
                  t.sha256().c_str());
    }
  }
  if (args.Has("json")) {
    PrintJson({{"serial", resp.serial()}, {"version", resp.version()}, {"table", req.table()},
               {"generating", req.generating()}, {"format", req.format()}, {"udc_axis_v", udcs},
               {"verdict", resp.verdict()}, {"released", resp.released()}, {"files", files}});
  }
  return 0;
}

}  // namespace

int RunRemoteExport(const std::vector<std::string>& argv, const FlagSpecs& flags) {
  auto args = ParseArgs(argv, flags);
  if (!args.ok()) std::fprintf(stderr, "fluxcal export: %s\n", std::string(args.status().message()).c_str());
  if (!args.ok() || args->positional.size() != 1 || !args->Get("out")) {
    std::fprintf(stderr, "usage: fluxcal export SERIAL --server ADDR --table mtpa|mtpv|fw|envelope --format "
                         "csv|json|h|cdfx|dcm|a2l [--points N] [--version N] [--ctype double|float|int16|int32] [--allow-extrapolation] "
                         "--out FILE [--json]\n");
    return 2;
  }
  if (auto e = CheckOutToStdout(*args); !e.empty()) {
    std::fprintf(stderr, "fluxcal export: %s\n", e.c_str());
    return 2;
  }
  const bool to_stdout = *args->Get("out") == "-";
  // A Udc axis: one file per voltage, as the local export names them.
  std::vector<double> udcs;
  if (auto a = args->Get("udc-axis-v")) {
    std::string e;
    if (args->Get("udc-v")) e = "flags --udc-v and --udc-axis-v: give one Udc or a Udc axis, not both";
    if (to_stdout) e = "--udc-axis-v writes one file per Udc: give --out FILE, not --out -";
    auto axis = pipeline::ParseUdcAxis(*a);
    if (e.empty() && !axis.ok()) e = std::string(axis.status().message());
    if (!e.empty()) {
      std::fprintf(stderr, "fluxcal export: %s\n", e.c_str());
      return 2;
    }
    udcs = *axis;
  }
  // The overwrite rule (cli/args.h) before the call; OUT.sig too, since the
  // service may sign (and a stale one must not sit beside a new table).
  const OutputPath out_path{"out", *args->Get("out")}, sig_path{"out", to_stdout ? "" : *args->Get("out") + ".sig"};
  std::vector<OutputPath> outputs = {out_path, sig_path};
  if (!udcs.empty()) {
    outputs.clear();
    for (double u : udcs) {
      outputs.push_back({"out", pipeline::UdcAxisPath(out_path.path, u)});
      outputs.push_back({"out", pipeline::UdcAxisPath(out_path.path, u) + ".sig"});
    }
  }
  if (auto e = CheckOverwrite(*args, outputs); !e.empty()) {
    std::fprintf(stderr, "fluxcal export: %s\n", e.c_str());
    return 1;
  }
  v1::ExportTableRequest req;
  req.set_serial(args->positional[0]);
  req.set_table(args->Get("table").value_or("mtpa"));
  req.set_format(args->Get("format").value_or("csv"));
  req.set_ctype(args->Get("ctype").value_or(""));
  req.set_allow_extrapolation(args->Has("allow-extrapolation"));
  req.set_allow_clamped(args->Has("allow-clamped"));
  req.set_generating(args->Has("generating"));
  {
    // --generating only with --table envelope: a usage error before the call.
    tables::TableSpec spec;
    spec.kind = req.table();
    spec.envelope_generating = req.generating();
    if (auto st = pipeline::CheckExportSpec(spec, tables::ExportRequest{}); !st.ok()) {
      std::fprintf(stderr, "fluxcal export: %s\n", std::string(st.message()).c_str());
      return 2;
    }
  }
  int n = 0;
  if (auto v = args->Get("points")) { if (!absl::SimpleAtoi(*v, &n)) return 2; req.set_points(n); }
  if (auto v = args->Get("speed-points")) { if (!absl::SimpleAtoi(*v, &n)) return 2; req.set_speed_points(n); }
  if (auto v = args->Get("version")) { if (!absl::SimpleAtoi(*v, &n)) return 2; req.set_version(n); }
  for (auto [flag, setter] : {std::pair<const char*, void (v1::ExportTableRequest::*)(double)>{
                                  "speed-max-rpm", &v1::ExportTableRequest::set_speed_max_rpm},
                              {"i-max-a", &v1::ExportTableRequest::set_i_max_a},
                              {"udc-v", &v1::ExportTableRequest::set_udc_v},
                              {"rs-ohm", &v1::ExportTableRequest::set_rs_ohm},
                              {"magnet-temp-c", &v1::ExportTableRequest::set_magnet_temp_c}}) {
    auto d = args->GetDouble(flag);
    if (!d.ok()) { std::fprintf(stderr, "%s\n", std::string(d.status().message()).c_str()); return 2; }
    if (d->has_value()) (req.*setter)(**d);
  }
  for (double u : udcs) req.add_udc_axis_v(u);
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  v1::ExportTableResponse resp;
  if (auto s = CallWithDeadline(*stub, &v1::CalibrationService::Stub::ExportTable, req, &resp, 120); !s.ok()) {
    return ReportRpcError("export", s);
  }
  if (!udcs.empty()) return WriteRemoteUdcAxis(*args, req, resp, udcs);
  if (auto st = WriteNewOutput(*args, out_path, resp.data()); !st.ok()) {
    std::fprintf(stderr, "fluxcal export: %s\n", std::string(st.message()).c_str());
    return 1;
  }
  if (!to_stdout && resp.signature().empty()) {
    std::error_code ec;   // --force replaced the table: an old signature goes with it
    std::filesystem::remove(sig_path.path, ec);
  }
  if (!resp.signature().empty() && to_stdout) {
    std::fprintf(stderr, "fluxcal export: the service signed the table; the signature is not written with --out -\n");
  } else if (!resp.signature().empty()) {
    if (auto st = WriteNewOutput(*args, sig_path, resp.signature()); !st.ok()) {
      std::fprintf(stderr, "fluxcal export: %s\n", std::string(st.message()).c_str());
      return 1;
    }
  }
  // sha256: of the bytes written (= sha256sum FILE); the reply's crc32 and
  // sha256 are over the values (payload) and printed under those names.
  const std::string file_sha256 = io::Sha256Hex(resp.data());
  const double clamped_share = resp.cells() > 0 ? static_cast<double>(resp.clamped_cells()) / resp.cells() : 0.0;
  if (resp.clamped_cells() > 0) {
    std::fprintf(stderr, "fluxcal export: warning: %d of %d cells (%.1f %%) clamped (requests beyond the limits)\n",
                 resp.clamped_cells(), resp.cells(), 100 * clamped_share);
  }
  if (args->Has("json")) {
    PrintJson({{"out", *args->Get("out")}, {"serial", resp.serial()}, {"version", resp.version()},
               {"table", req.table()}, {"generating", req.generating()},
               {"format", req.format()}, {"sha256", file_sha256},
               {"payload_crc32", resp.crc32()}, {"payload_sha256", resp.sha256()},
               {"cells", resp.cells()}, {"clamped_cells", resp.clamped_cells()},
               {"clamped_share", clamped_share}, {"verdict", resp.verdict()},
               {"released", resp.released()}, {"bytes", resp.data().size()}});
  } else {
    std::fprintf(to_stdout ? stderr : stdout, "%s: %s v%d %s table (%s), verdict %s, %s\n  sha256 %s (file)\n  payload_crc32 %s payload_sha256 %s (values)\n",
                args->Get("out")->c_str(), resp.serial().c_str(), resp.version(), req.table().c_str(),
                req.format().c_str(), resp.verdict().c_str(), resp.released() ? "released" : "not released",
                file_sha256.c_str(), resp.crc32().c_str(), resp.sha256().c_str());
  }
  return 0;
}

}  // namespace fluxcal::cli
