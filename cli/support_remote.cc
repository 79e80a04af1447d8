#include "cli/support_remote.h"

#include <chrono>
#include <cstdio>
#include <iostream>

#include <grpcpp/grpcpp.h>

#include "absl/strings/numbers.h"
#include "cli/args.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {

std::unique_ptr<v1::CalibrationService::Stub> MakeStub(const std::string& address) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  return v1::CalibrationService::NewStub(
      grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args));
}

int ReportRpcError(const char* cmd, const grpc::Status& s) {
  static const char* kNames[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED",
                                 "NOT_FOUND", "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED",
                                 "FAILED_PRECONDITION", "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED",
                                 "INTERNAL", "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  const int c = static_cast<int>(s.error_code());
  std::fprintf(stderr, "fluxcal %s: %s: %s\n", cmd, c >= 0 && c <= 16 ? kNames[c] : "ERROR",
               s.error_message().c_str());
  return 1;
}

namespace {
void Deadline(grpc::ClientContext* ctx, int seconds) {
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
}
}  // namespace

int RunRemoteQuery(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, {"server", "id-a", "iq-a", "version"}, {"json"});
  if (!args.ok() || args->positional.size() != 1) {
    std::fprintf(stderr, "usage: fluxcal query SERIAL --server ADDR --id-a A --iq-a A [--version N] [--json]\n");
    return 2;
  }
  auto id = args->GetDouble("id-a");
  auto iq = args->GetDouble("iq-a");
  if (!id.ok() || !iq.ok() || !id->has_value() || !iq->has_value()) {
    std::fprintf(stderr, "fluxcal query: need --id-a and --iq-a\n");
    return 2;
  }
  auto stub = MakeStub(*args->Get("server"));
  v1::QueryFluxRequest req;
  req.set_serial(args->positional[0]);
  int version = 0;
  if (auto v = args->Get("version"); v && !absl::SimpleAtoi(*v, &version)) return 2;
  req.set_version(version);
  auto* p = req.add_points();
  p->set_id_a(**id);
  p->set_iq_a(**iq);
  v1::QueryFluxResponse resp;
  grpc::ClientContext ctx;
  Deadline(&ctx, 30);
  auto s = stub->QueryFlux(&ctx, req, &resp);
  if (!s.ok()) return ReportRpcError("query", s);
  const auto& v = resp.values(0);
  if (args->Has("json")) {
    std::cout << nlohmann::json{{"serial", resp.serial()}, {"version", resp.version()}, {"id_a", v.id_a()},
                                {"iq_a", v.iq_a()}, {"psi_d_wb", v.psi_d_wb()}, {"psi_q_wb", v.psi_q_wb()},
                                {"ldd_h", v.ldd_h()}, {"lqq_h", v.lqq_h()}, {"ldq_h", v.ldq_h()},
                                {"ld_app_h", v.ld_app_h()}, {"lq_app_h", v.lq_app_h()}, {"torque_nm", v.torque_nm()},
                                {"psi_d_wb_std", v.psi_d_wb_std()}, {"ldd_h_std", v.ldd_h_std()},
                                {"lqq_h_std", v.lqq_h_std()}, {"torque_nm_std", v.torque_nm_std()},
                                {"extrapolated", v.extrapolated()}}
                     .dump(2, ' ', false, nlohmann::json::error_handler_t::replace)
              << "\n";
  } else {
    std::printf("serial %s v%d at id = %g A, iq = %g A: psi_d %.6g Wb, psi_q %.6g Wb, Ldd %.5g mH, Lqq %.5g mH, "
                "Ldq %.4g mH, torque %.4g N m%s\n",
                resp.serial().c_str(), resp.version(), v.id_a(), v.iq_a(), v.psi_d_wb(), v.psi_q_wb(),
                v.ldd_h() * 1e3, v.lqq_h() * 1e3, v.ldq_h() * 1e3, v.torque_nm(),
                v.extrapolated() ? " (extrapolated)" : "");
  }
  return 0;
}

int RunRemoteExport(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, {"server", "table", "format", "points", "speed-points", "speed-max-rpm", "i-max-a",
                               "udc-v", "out", "version"},
                        {"json"});
  if (!args.ok() || args->positional.size() != 1 || !args->Get("out")) {
    std::fprintf(stderr, "usage: fluxcal export SERIAL --server ADDR --table mtpa|mtpv|fw --format "
                         "csv|json|h|cdfx|dcm [--points N] [--version N] --out FILE [--json]\n");
    return 2;
  }
  v1::ExportTableRequest req;
  req.set_serial(args->positional[0]);
  req.set_table(args->Get("table").value_or("mtpa"));
  req.set_format(args->Get("format").value_or("csv"));
  int n = 0;
  if (auto v = args->Get("points")) { if (!absl::SimpleAtoi(*v, &n)) return 2; req.set_points(n); }
  if (auto v = args->Get("speed-points")) { if (!absl::SimpleAtoi(*v, &n)) return 2; req.set_speed_points(n); }
  if (auto v = args->Get("version")) { if (!absl::SimpleAtoi(*v, &n)) return 2; req.set_version(n); }
  for (auto [flag, setter] : {std::pair<const char*, void (v1::ExportTableRequest::*)(double)>{
                                  "speed-max-rpm", &v1::ExportTableRequest::set_speed_max_rpm},
                              {"i-max-a", &v1::ExportTableRequest::set_i_max_a},
                              {"udc-v", &v1::ExportTableRequest::set_udc_v}}) {
    auto d = args->GetDouble(flag);
    if (!d.ok()) { std::fprintf(stderr, "%s\n", std::string(d.status().message()).c_str()); return 2; }
    if (d->has_value()) (req.*setter)(**d);
  }
  auto stub = MakeStub(*args->Get("server"));
  v1::ExportTableResponse resp;
  grpc::ClientContext ctx;
  Deadline(&ctx, 120);
  auto s = stub->ExportTable(&ctx, req, &resp);
  if (!s.ok()) return ReportRpcError("export", s);
  if (auto st = io::WriteFileAtomically(*args->Get("out"), resp.data()); !st.ok()) {
    std::fprintf(stderr, "fluxcal export: %s\n", std::string(st.message()).c_str());
    return 1;
  }
  if (args->Has("json")) {
    std::cout << nlohmann::json{{"out", *args->Get("out")}, {"serial", resp.serial()}, {"version", resp.version()},
                                {"table", req.table()}, {"format", req.format()}, {"crc32", resp.crc32()},
                                {"sha256", resp.sha256()}, {"clamped_cells", resp.clamped_cells()},
                                {"bytes", resp.data().size()}}
                     .dump(2, ' ', false, nlohmann::json::error_handler_t::replace)
              << "\n";
  } else {
    std::printf("%s: %s v%d %s table (%s), crc32 %s sha256 %s\n", args->Get("out")->c_str(), resp.serial().c_str(),
                resp.version(), req.table().c_str(), req.format().c_str(), resp.crc32().c_str(), resp.sha256().c_str());
  }
  return 0;
}

}  // namespace fluxcal::cli
