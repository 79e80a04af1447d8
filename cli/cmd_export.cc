// fluxcal export calibration.json --table mtpa|mtpv|fw|envelope --format csv|json|h|cdfx|dcm|a2l
//                [--points N] [--speed-points M] [--speed-max-rpm R] [--i-max-a A]
//                [--generating] [--udc-v V | --udc-axis-v V1,V2,...|LO:HI:N] [--magnet-temp-c C] [--rs-ohm R] [--allow-clamped] [--ctype double|float|int16|int32] [--allow-extrapolation]
//                [--svg FILE] [--sign-key ED25519.key] --out FILE [--json]
// With --sign-key, FILE.sig holds a detached Ed25519 signature
// (pipeline/signing.h; `fluxcal verify FILE --pubkey KEY.pub`).
// Builds an ECU lookup table from a fitted calibration and writes it with
// limits, provenance, flags and the CRC-32 / SHA-256 of its payload (the
// values, docs/tables.md) inside. It prints the SHA-256 of the written file
// (`sha256`, equal to `sha256sum FILE`) and the payload checksums under
// their own names (`payload_crc32`, `payload_sha256`).
#include <cstdio>
#include <filesystem>
#include <system_error>

#include "absl/status/status.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_remote.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"
#include "io/sha256.h"
#include "pipeline/export.h"
#include "pipeline/pipeline.h"
#include "pipeline/signing.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("export", m, code); }

// Local (calibration file) and remote (--server, serial) export share these;
// --svg and --sign-key are local only, --server and --version remote only.
const FlagSpecs kExportFlags = {
    OutFlag("table file"),
    {"table", "T", "mtpa|mtpv|fw|envelope (default mtpa; envelope: max torque and power over speed)"},
    {"format", "F", "csv|json|h|cdfx|dcm|a2l (default csv)"},
    {"points", "N", "at most N rows of a curve / torque axis of the fw map, round breakpoints (default 64)"},
    {"generating", "", "with --table envelope: the generating limit (torque and power <= 0), labels "
                       "FLUXCAL_ENVELOPE_GENERATING_* beside the motoring FLUXCAL_ENVELOPE_*"},
    {"speed-points", "N", "fw, envelope: at most N round speeds on the speed axis (default 32)"},
    {"speed-max-rpm", "RPM", "fw, envelope: speed axis range 0..RPM, mechanical rpm (default 6000)"},
    {"i-max-a", "A", "current limit, A peak (default the measured limit of the calibration)"},
    {"udc-v", "V", "DC-link voltage, V (default the calibration's; fw, mtpv and envelope refuse without one)"},
    {"udc-axis-v", "LIST", "a Udc axis, V1,V2,... or LO:HI:N volts (at most 32): one table per Udc, written to "
                           "OUT_udc<V>v.EXT with labels tagged _UDC<V>V (not with --udc-v; with --server the "
                           "service computes them, ExportTable udc_axis_v)"},
    {"magnet-temp-c", "C", "tables at this magnet temperature, degC (needs the calibration's own "
                           "psi_pm temperature coefficient and the magnet temperature of its flux map; refused "
                           "without them)"},
    {"rs-ohm", "R", "stator resistance, ohm (default the calibration's; fw and envelope refuse without one)"},
    {"allow-clamped", "", "export a table with more than half of its cells clamped (refused otherwise)"},
    {"ctype", "T", "element type of --format h and a2l: double|float|int16|int32 (fixed point, LSB per quantity; default double)"},
    {"allow-extrapolation", "", "compute beyond the measured current region (cells flagged extrapolated)"},
    {"svg", "FILE", "local only: also plot the curves / map (SVG)"},
    {"sign-key", "KEY", "local only: Ed25519 private key; writes OUT.sig (not with --out -)"},
    ServerFlag("export a serial's stored calibration from the service"),
    kServerVersionFlag,
    JsonFlag("a summary (checksums, limits, verdict)"),
    kForceFlag,
};

// "envelope (generating)" for the generating envelope, else the kind.
std::string TableWhat(const tables::TableSpec& spec) {
  return spec.kind == "envelope" && spec.envelope_generating ? "envelope (generating)" : spec.kind;
}

// --udc-axis-v: one export per Udc through the pipeline, each file named
// and checked as a single export's (UdcAxisPath, the overwrite rule), the
// figure (--svg) one envelope over every Udc, or one figure per Udc file
// for the other tables.
int RunUdcAxisExport(const ParsedArgs& args, const fit::Calibration& cal, const tables::TableSpec& spec,
                     const tables::ExportRequest& request, const std::vector<double>& udcs, tables::CType ctype) {
  const std::string out_file = *args.Get("out"), svg = args.Get("svg").value_or("");
  const std::string format = args.Get("format").value_or("csv");
  std::vector<OutputPath> outputs;
  for (double u : udcs) {
    outputs.push_back({"out", pipeline::UdcAxisPath(out_file, u)});
    outputs.push_back({"out", pipeline::UdcAxisPath(out_file, u) + ".sig"});
    if (!svg.empty() && spec.kind != "envelope") outputs.push_back({"svg", pipeline::UdcAxisPath(svg, u)});
  }
  if (!svg.empty() && spec.kind == "envelope") outputs.push_back({"svg", svg});
  if (auto e = CheckOverwrite(args, outputs); !e.empty()) return Fail(e);
  const std::string what = TableWhat(spec);
  std::fprintf(stderr, "export: building %s tables at %zu DC-link voltages for %s\n", what.c_str(), udcs.size(),
               spec.serial.c_str());
  tables::ExportOptions options;
  options.ctype = ctype;
  auto built = pipeline::ExportCalibrationOverUdc(cal, spec, request, udcs, format, options);
  if (!built.ok()) return Fail(std::string(built.status().message()), ExitCodeFor(built.status()));
  if (!built->empty() && built->front().result.table.magnet_temperature) {
    std::fprintf(stderr, "export: note: %s\n",
                 tables::MagnetTemperatureNote(*built->front().result.table.magnet_temperature).c_str());
  }
  std::optional<std::string> key;
  if (auto key_path = args.Get("sign-key")) {
    auto k = io::ReadFileToString(*key_path);
    if (!k.ok()) return Fail("--sign-key " + *key_path + ": cannot read", 2);
    key = *k;
  }
  nlohmann::json files = nlohmann::json::array();
  std::vector<const pipeline::ExportResult*> envelopes;
  for (const auto& b : *built) {
    const pipeline::ExportResult& r = b.result;
    const std::string path = pipeline::UdcAxisPath(out_file, b.udc_v);
    if (r.clamped.clamped > 0) {
      std::fprintf(stderr, "export: warning: Udc %g V: %zu of %zu cells (%.1f %%) clamped: %s%s\n", b.udc_v,
                   r.clamped.clamped, r.clamped.cells, 100 * r.clamped.share, r.clamped.why.c_str(),
                   r.clamped.share > tables::kMaxClampedShare ? " (exported on --allow-clamped)" : "");
    }
    if (auto st = WriteNewOutput(args, {"out", path}, r.exported.bytes); !st.ok()) return Fail(std::string(st.message()));
    std::string sig_path;
    if (key) {
      auto sig = pipeline::SignExport(r.exported.bytes, *key);
      if (!sig.ok()) return Fail("--sign-key: " + std::string(sig.status().message()));
      sig_path = path + ".sig";
      if (auto st = WriteNewOutput(args, {"out", sig_path}, *sig); !st.ok()) return Fail(std::string(st.message()));
    } else {
      std::error_code ec;
      std::filesystem::remove(path + ".sig", ec);
    }
    if (!svg.empty() && spec.kind != "envelope") {
      if (auto st = WriteNewOutput(args, {"svg", pipeline::UdcAxisPath(svg, b.udc_v)},
                                   pipeline::ExportFigureSvg(cal, spec, r));
          !st.ok()) {
        return Fail(std::string(st.message()));
      }
    }
    envelopes.push_back(&r);
    auto written = io::ReadFileToString(path);
    if (!written.ok()) return Fail(std::string(written.status().message()));
    char crc[16];
    std::snprintf(crc, sizeof crc, "%08x", r.exported.payload_crc32);
    const std::string file_sha256 = io::Sha256Hex(*written);
    files.push_back({{"out", path}, {"udc_v", b.udc_v}, {"label_tag", r.table.label_tag}, {"cells", r.clamped.cells},
                     {"clamped_cells", r.clamped.clamped}, {"clamped_share", r.clamped.share},
                     {"extrapolated_cells", r.extrapolated_cells}, {"u_max_v", r.limits.limits.UMaxV()},
                     {"sha256", file_sha256}, {"payload_crc32", crc}, {"payload_sha256", r.exported.payload_sha256},
                     {"bytes", written->size()}, {"signature", sig_path}});
    if (!args.Has("json")) {
      std::printf("%s: %s table at Udc %g V (labels %s), %zu cells (%zu clamped at limits, %d extrapolated)\n"
                  "  sha256 %s (file)\n  payload_crc32 %s payload_sha256 %s (values, docs/tables.md)\n",
                  path.c_str(), what.c_str(), b.udc_v, tables::Label(r.table, "*").c_str(), r.clamped.cells,
                  r.clamped.clamped, r.extrapolated_cells, file_sha256.c_str(), crc, r.exported.payload_sha256.c_str());
    }
  }
  if (!svg.empty() && spec.kind == "envelope") {
    if (auto st = WriteNewOutput(args, {"svg", svg}, pipeline::EnvelopeFigureSvg(envelopes)); !st.ok()) {
      return Fail(std::string(st.message()));
    }
  }
  if (args.Has("json")) {
    const auto& lim = built->front().result.limits;
    nlohmann::json j = {{"table", spec.kind}, {"generating", spec.envelope_generating}, {"format", format},
                        {"serial", spec.serial},
                        {"calibration_version", spec.calibration_version}, {"udc_axis_v", udcs},
                        {"i_max_a", lim.limits.i_max_a},
                        {"rs_ohm", lim.limits.rs_ohm ? nlohmann::json(*lim.limits.rs_ohm) : nlohmann::json()},
                        {"ctype", pipeline::ExportCTypeName(ctype)}, {"files", files}, {"svg", svg}};
    j["sources"] = {{"i_max_a", lim.i_max_source}, {"udc_v", "--udc-axis-v"}, {"rs_ohm", lim.rs_source}};
    PrintJson(j);
  }
  return 0;
}

int RunExport(const std::vector<std::string>& argv) {
  for (const auto& a : argv) {
    if (a == "--server" || a.rfind("--server=", 0) == 0) {
      return RunRemoteExport(argv, WithoutFlags(kExportFlags, {"svg", "sign-key"}));
    }
  }
  auto args = ParseArgs(argv, WithoutFlags(kExportFlags, {"server", "version"}));
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  if (auto e = CheckOutToStdout(*args); !e.empty()) return Fail(e, 2);
  const bool to_stdout = args->Get("out").value_or("") == "-";
  if (to_stdout && args->Get("sign-key")) return Fail("--sign-key writes OUT.sig: give --out FILE, not --out -", 2);
  if (args->positional.size() != 1 || !args->Get("out")) {
    return Fail("usage: fluxcal export calibration.json --table mtpa|mtpv|fw|envelope --format "
                "csv|json|h|cdfx|dcm|a2l [--points N] [--ctype double|float|int16|int32] [--allow-extrapolation] --out FILE", 2);
  }
  auto cal = pipeline::LoadCalibrationFile(args->positional[0]);
  if (!cal.ok()) return Fail(std::string(cal.status().message()));
  if (auto fmt = pipeline::CheckExportFormat(args->Get("format").value_or("csv")); !fmt.ok()) {
    return Fail(std::string(fmt.message()), 2);
  }
  auto ctype = pipeline::ParseExportCType(args->Get("ctype").value_or("double"));
  if (!ctype.ok()) return Fail(std::string(ctype.status().message()), 2);
  tables::TableSpec spec;
  spec.kind = args->Get("table").value_or("mtpa");
  spec.serial = cal->serial();
  spec.calibration_version = cal->version;
  spec.model = cal->family().Name();
  // A calibration file carries no verdict or release decision (those live in
  // the store, fluxcal release): say so in the file rather than guess.
  spec.verdict = tables::kVerdictUnknown;
  spec.release_state = tables::kReleaseUnknown;
  spec.allow_extrapolation = args->Has("allow-extrapolation");
  spec.envelope_generating = args->Has("generating");
  auto get_int = [&](const char* flag, int* v) {
    if (auto s = args->Get(flag)) return absl::SimpleAtoi(*s, v);
    return true;
  };
  if (!get_int("points", &spec.points) || !get_int("speed-points", &spec.speed_points)) {
    return Fail("flags --points/--speed-points: expected integers", 2);
  }
  // Limits: the flags', else the calibration's, under the one export rule
  // (tables/export_rule.h) the service applies too.
  tables::ExportRequest request;
  request.allow_clamped = args->Has("allow-clamped");
  if (auto v = args->GetDouble("speed-max-rpm"); !v.ok()) {
    return Fail(std::string(v.status().message()), 2);
  } else if (v->has_value()) {
    spec.speed_max_rpm = **v;
  }
  for (auto [flag, dst] : {std::pair<const char*, std::optional<double>*>{"i-max-a", &request.i_max_a},
                           {"udc-v", &request.udc_v}, {"rs-ohm", &request.rs_ohm}}) {
    auto v = args->GetDouble(flag);
    if (!v.ok()) return Fail(std::string(v.status().message()), 2);
    *dst = *v;
  }
  if (auto v = args->GetDouble("magnet-temp-c"); !v.ok()) {
    return Fail(std::string(v.status().message()), 2);
  } else {
    request.magnet_temp_c = *v;
  }
  // --generating with a table other than the envelope: a usage error
  // before anything is read or written (the rule is the pipeline's).
  if (auto s = pipeline::CheckExportSpec(spec, request); !s.ok()) return Fail(std::string(s.message()), 2);
  std::optional<std::vector<double>> udc_axis;
  if (auto a = args->Get("udc-axis-v")) {
    if (request.udc_v) return Fail("flags --udc-v and --udc-axis-v: give one Udc or a Udc axis, not both", 2);
    if (to_stdout) return Fail("--udc-axis-v writes one file per Udc: give --out FILE, not --out -", 2);
    auto axis = pipeline::ParseUdcAxis(*a);
    if (!axis.ok()) return Fail(std::string(axis.status().message()), 2);
    udc_axis = *axis;
  }
  if (udc_axis) return RunUdcAxisExport(*args, *cal, spec, request, *udc_axis, *ctype);
  // Every flag checked: the overwrite rule (cli/args.h), before any work.
  // OUT.sig counts as an output whether or not this export signs: a
  // signature left from an earlier table would vouch for bytes no longer there.
  const std::string out_file = *args->Get("out");
  const OutputPath out_path{"out", out_file}, svg_path{"svg", args->Get("svg").value_or("")};
  const OutputPath sig_path_out{"out", to_stdout ? "" : out_file + ".sig"};
  if (auto e = CheckOverwrite(*args, {out_path, sig_path_out, svg_path}); !e.empty()) return Fail(e);
  if (spec.kind == "envelope") {
    std::fprintf(stderr, "export: building %s table (at most %d speeds) for %s\n", TableWhat(spec).c_str(),
                 spec.speed_points, spec.serial.c_str());
  } else {
    std::fprintf(stderr, "export: building %s table (at most %d points) for %s\n", spec.kind.c_str(), spec.points,
                 spec.serial.c_str());
  }
  tables::ExportOptions options;
  options.ctype = *ctype;
  // The one export path (pipeline/export.h), the service's too.
  auto built = pipeline::ExportCalibration(*cal, spec, request, args->Get("format").value_or("csv"), options);
  if (!built.ok()) {
    // A flag to give or correct is a usage error (2); a table refused for
    // what it would contain (mostly clamped, no MTPV point inside) is not (1).
    return Fail(std::string(built.status().message()), ExitCodeFor(built.status()));
  }
  const tables::Table* table = &built->table;
  const tables::MachineLimits& lim = built->limits.limits;
  if (!built->limits.overridden.empty()) {
    std::fprintf(stderr, "export: note: %s\n", built->limits.overridden.c_str());
  }
  if (table->magnet_temperature) {
    std::fprintf(stderr, "export: note: %s\n", tables::MagnetTemperatureNote(*table->magnet_temperature).c_str());
  }
  const tables::ClampSummary& clamp = built->clamped;
  if (clamp.clamped > 0) {
    std::fprintf(stderr, "export: warning: %zu of %zu cells (%.1f %%) clamped: %s%s\n", clamp.clamped, clamp.cells,
                 100 * clamp.share, clamp.why.c_str(),
                 clamp.share > tables::kMaxClampedShare ? " (exported on --allow-clamped)" : "");
  }
  const tables::Exported* out = &built->exported;
  if (auto st = WriteNewOutput(*args, out_path, out->bytes); !st.ok()) return Fail(std::string(st.message()));
  std::string sig_path;
  if (!to_stdout && !args->Get("sign-key")) {
    // --force replaced the table: a signature of the old one goes with it.
    std::error_code ec;
    std::filesystem::remove(sig_path_out.path, ec);
  }
  if (auto key_path = args->Get("sign-key")) {
    auto key = io::ReadFileToString(*key_path);
    if (!key.ok()) return Fail("--sign-key " + *key_path + ": cannot read", 2);
    auto sig = pipeline::SignExport(out->bytes, *key);
    if (!sig.ok()) return Fail("--sign-key: " + std::string(sig.status().message()));
    sig_path = *args->Get("out") + ".sig";
    if (auto st = WriteNewOutput(*args, {"out", sig_path}, *sig); !st.ok()) return Fail(std::string(st.message()));
  }
  if (args->Get("svg")) {
    if (auto st = WriteNewOutput(*args, svg_path, pipeline::ExportFigureSvg(*cal, spec, *built)); !st.ok()) {
      return Fail(std::string(st.message()));
    }
  }
  const size_t extrapolated = static_cast<size_t>(built->extrapolated_cells);
  char crc[16];
  std::snprintf(crc, sizeof crc, "%08x", out->payload_crc32);
  // The file checksum is recomputed from the bytes just written, so that
  // what is printed is what `sha256sum FILE` gives.
  auto written = to_stdout ? absl::StatusOr<std::string>(out->bytes) : io::ReadFileToString(*args->Get("out"));
  if (!written.ok()) return Fail(std::string(written.status().message()));
  const std::string file_sha256 = io::Sha256Hex(*written);
  if (args->Has("json")) {
    // Unknown limits are null, with where each known one came from.
    auto opt = [](const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(); };
    nlohmann::json j = {{"out", *args->Get("out")}, {"table", spec.kind}, {"generating", spec.envelope_generating},
                        {"label_tag", table->label_tag}, {"format", args->Get("format").value_or("csv")},
                        {"serial", spec.serial}, {"calibration_version", spec.calibration_version},
                        {"rows", clamp.cells}, {"cells", clamp.cells}, {"clamped_rows", clamp.clamped},
                        {"clamped_cells", clamp.clamped}, {"clamped_share", clamp.share},
                        {"extrapolated_cells", extrapolated},
                        {"i_max_a", lim.i_max_a}, {"udc_v", opt(lim.udc_v)}, {"rs_ohm", opt(lim.rs_ohm)},
                        {"u_max_v", lim.udc_v ? nlohmann::json(lim.UMaxV()) : nlohmann::json()},
                        {"verdict", table->verdict}, {"release_state", table->release_state},
                        {"sha256", file_sha256}, {"payload_crc32", crc}, {"payload_sha256", out->payload_sha256},
                        {"bytes", written->size()}, {"signature", sig_path}};
    auto src = [](const std::string& v) { return v.empty() ? nlohmann::json() : nlohmann::json(v); };
    j["sources"] = {{"i_max_a", src(built->limits.i_max_source)}, {"udc_v", src(built->limits.udc_source)},
                    {"rs_ohm", src(built->limits.rs_source)}};
    // The magnet temperature the table was computed at (null: the flux map's own).
    j["magnet_temperature"] = nullptr;
    if (const auto& mt = table->magnet_temperature) {
      j["magnet_temperature"] = {{"at_c", mt->at_c}, {"reference_c", mt->reference_c},
                                 {"reference_spread_k", opt(mt->reference_spread_k)},
                                 {"alpha_per_k", mt->alpha_per_k}, {"psi_pm_scale", mt->Scale()}};
    }
    // h and a2l in fixed point: the scale of each quantity as the file states it.
    j["ctype"] = pipeline::ExportCTypeName(*ctype);
    j["fixed_point"] = nlohmann::json::array();
    for (const auto& q : out->fixed_point) {
      j["fixed_point"].push_back({{"unit", q.unit}, {"arrays", q.arrays}, {"bits", q.bits}, {"lsb", q.lsb},
                                  {"offset", q.offset}, {"min_value", q.min_value}, {"max_value", q.max_value}});
    }
    PrintJson(j);
  } else {
    const std::string u_max = lim.udc_v ? absl::StrFormat("u_max %.6g V", lim.UMaxV()) : "no voltage limit (Udc not known)";
    std::fprintf(to_stdout ? stderr : stdout, "%s: %s table, %zu cells (%zu clamped at limits, %zu extrapolated), i_max %.6g A, %s\n"
                "  sha256 %s (file)\n  payload_crc32 %s payload_sha256 %s (values, docs/tables.md)\n",
                args->Get("out")->c_str(), TableWhat(spec).c_str(), clamp.cells, clamp.clamped, extrapolated,
                lim.i_max_a, u_max.c_str(), file_sha256.c_str(), crc, out->payload_sha256.c_str());
    for (const auto& q : out->fixed_point) {
      std::fprintf(to_stdout ? stderr : stdout, "  %s fixed point: %s LSB %.17g %s, offset %g (%s)\n",
                   pipeline::ExportCTypeName(*ctype), q.unit.c_str(), q.lsb, q.unit.c_str(), q.offset,
                   absl::StrJoin(q.arrays, ", ").c_str());
    }
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("export", "export MTPA / MTPV / field-weakening / envelope tables for ECU flashing", RunExport,
                         "fluxcal export calibration.json --out FILE [--force] [--table mtpa|mtpv|fw|envelope [--generating]] [--format csv|json|h|cdfx|dcm|a2l] [flags]\n"
                         "fluxcal export SERIAL --server ADDR [--version N] --out FILE [--force] [--table T] [--format F] [flags]",
                         kExportFlags);

}  // namespace fluxcal::cli
