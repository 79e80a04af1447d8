#include "pipeline/export.h"

#include <utility>

#include "absl/strings/str_cat.h"

#include "pipeline/pipeline.h"

namespace fluxcal::pipeline {

absl::Status CheckExportFormat(const std::string& name) { return tables::ParseFormat(name).status(); }

absl::StatusOr<tables::CType> ParseExportCType(const std::string& name) { return tables::ParseCType(name); }

const char* ExportCTypeName(tables::CType ct) { return tables::CTypeName(ct); }

namespace {

// A built table written as `fmt`, with its counts.
absl::StatusOr<ExportResult> Write(tables::BuiltExport* built, tables::Format fmt,
                                   const tables::ExportOptions& options) {
  auto e = tables::Export(built->table, fmt, options);
  if (!e.ok()) return e.status();
  ExportResult r;
  r.exported = std::move(*e);
  r.version = built->table.calibration_version;
  r.clamped = built->clamped;
  r.cells = static_cast<int>(built->clamped.cells);
  r.clamped_cells = static_cast<int>(built->clamped.clamped);
  for (auto c : built->table.extrapolated) r.extrapolated_cells += c;
  r.table = std::move(built->table);
  r.limits = std::move(built->limits);
  return r;
}

}  // namespace

absl::StatusOr<ExportResult> ExportCalibration(const fit::Calibration& cal, const tables::TableSpec& spec,
                                               const tables::ExportRequest& request, const std::string& format,
                                               const tables::ExportOptions& options) {
  // The format first: a wrong name costs no table.
  auto fmt = tables::ParseFormat(format);
  if (!fmt.ok()) return fmt.status();
  auto built = tables::BuildExportTable(cal, spec, request);
  if (!built.ok()) return built.status();
  return Write(&*built, *fmt, options);
}

absl::StatusOr<std::vector<UdcAxisExport>> ExportCalibrationOverUdc(const fit::Calibration& cal,
                                                                    const tables::TableSpec& spec,
                                                                    const tables::ExportRequest& request,
                                                                    const std::vector<double>& udc_axis_v,
                                                                    const std::string& format,
                                                                    const tables::ExportOptions& options) {
  auto fmt = tables::ParseFormat(format);
  if (!fmt.ok()) return fmt.status();
  auto built = tables::BuildExportTablesOverUdc(cal, spec, request, udc_axis_v);
  if (!built.ok()) return built.status();
  std::vector<UdcAxisExport> out;
  for (size_t k = 0; k < built->size(); ++k) {
    auto r = Write(&(*built)[k], *fmt, options);
    if (!r.ok()) return r.status();
    out.push_back({udc_axis_v[k], *std::move(r)});
  }
  return out;
}

std::string UdcAxisPath(const std::string& path, double udc_v) {
  const std::string tag = "_" + tables::UdcTag(udc_v);
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  const bool has_ext = dot != std::string::npos && dot > 0 && (slash == std::string::npos || dot > slash + 1);
  return has_ext ? path.substr(0, dot) + tag + path.substr(dot) : path + tag;
}

absl::StatusOr<std::vector<double>> ParseUdcAxis(const std::string& text) { return tables::ParseUdcAxis(text); }

std::string EnvelopeFigureSvg(const std::vector<const ExportResult*>& envelopes) {
  std::vector<tables::Table> t;
  for (const auto* e : envelopes) t.push_back(e->table);
  return tables::PlotEnvelopeSvg(t);
}

namespace {

// A stored version with the spec its files are written under: serial,
// version and model from the store, verdict and release state too, so
// that a flashing tool that only sees the file sees them.
struct StoredExport {
  fit::Calibration cal;
  tables::TableSpec spec;
  std::string verdict;
  bool released = false;
};

absl::StatusOr<StoredExport> LoadForExport(storage::Store& store, const std::string& serial, int version,
                                           const tables::TableSpec& spec_in) {
  auto cal = LoadCalibration(store, serial, version);
  if (!cal.ok()) return cal.status();
  auto row = store.GetCalibration(serial, cal->version);
  if (!row.ok()) return row.status();
  auto released = store.IsReleased(serial, cal->version);
  if (!released.ok()) return released.status();
  StoredExport out{*std::move(cal), spec_in, row->verdict, *released};
  tables::TableSpec& spec = out.spec;
  spec.serial = serial;
  spec.calibration_version = out.cal.version;
  spec.model = out.cal.family().Name();
  spec.verdict = row->verdict.empty() ? tables::kVerdictUnknown : row->verdict;
  spec.release_state = *released ? tables::kReleased : tables::kNotReleased;
  return out;
}

}  // namespace

absl::Status CheckExportSpec(const tables::TableSpec& spec, const tables::ExportRequest& request) {
  return tables::CheckExportSpec(spec, request);
}

absl::StatusOr<ExportResult> ExportTable(storage::Store& store, const std::string& serial, int version,
                                         const tables::TableSpec& spec_in, const tables::ExportRequest& request,
                                         const std::string& format, const tables::ExportOptions& options) {
  if (auto fmt = tables::ParseFormat(format); !fmt.ok()) return fmt.status();
  if (auto s = tables::CheckExportSpec(spec_in, request); !s.ok()) return s;
  auto stored = LoadForExport(store, serial, version, spec_in);
  if (!stored.ok()) return stored.status();
  auto r = ExportCalibration(stored->cal, stored->spec, request, format, options);
  if (!r.ok()) return r.status();
  r->version = stored->cal.version;
  r->verdict = stored->verdict;
  r->released = stored->released;
  return r;
}

absl::StatusOr<StoredUdcAxisExport> ExportTableOverUdc(storage::Store& store, const std::string& serial, int version,
                                                       const tables::TableSpec& spec_in,
                                                       const tables::ExportRequest& request,
                                                       const std::vector<double>& udc_axis_v,
                                                       const std::string& format,
                                                       const tables::ExportOptions& options) {
  if (auto fmt = tables::ParseFormat(format); !fmt.ok()) return fmt.status();
  if (auto s = tables::CheckExportSpec(spec_in, request); !s.ok()) return s;
  auto stored = LoadForExport(store, serial, version, spec_in);
  if (!stored.ok()) return stored.status();
  auto axis = ExportCalibrationOverUdc(stored->cal, stored->spec, request, udc_axis_v, format, options);
  if (!axis.ok()) return axis.status();
  StoredUdcAxisExport out;
  out.version = stored->cal.version;
  out.verdict = stored->verdict;
  out.released = stored->released;
  out.tables = *std::move(axis);
  for (auto& t : out.tables) {
    t.result.version = out.version;
    t.result.verdict = out.verdict;
    t.result.released = out.released;
  }
  return out;
}

std::string ExportFileName(const std::string& serial, const tables::TableSpec& spec, const std::string& format,
                           double udc_v) {
  const std::string base = absl::StrCat(serial, serial.empty() ? "" : "_", spec.kind,
                                        spec.kind == "envelope" && spec.envelope_generating ? "_generating" : "", ".",
                                        format);
  return udc_v > 0 ? UdcAxisPath(base, udc_v) : base;
}

std::string ExportFigureSvg(const fit::Calibration& cal, const tables::TableSpec& spec, const ExportResult& exported) {
  const tables::Table& table = exported.table;
  const tables::MachineLimits& lim = exported.limits.limits;
  if (spec.kind == "fw") return tables::PlotMapSvg(table, "id_a");
  if (spec.kind == "envelope") return tables::PlotEnvelopeSvg({table});
  tables::TableSpec ms = spec;
  ms.measured_current_limit_a = table.measured_current_limit_a;   // as the export rule set it
  ms.magnet_temperature = table.magnet_temperature;
  ms.kind = "mtpa";
  auto mtpa = spec.kind == "mtpa" ? absl::StatusOr<tables::Table>(table) : tables::BuildTable(cal, lim, ms);
  if (spec.kind == "mtpv") {
    // The MTPV table's own figure; MTPA beside it for reference.
    return tables::PlotMtpvSvg(cal, lim, table, mtpa.ok() ? &*mtpa : nullptr);
  }
  ms.kind = "mtpv";
  auto mtpv = tables::BuildTable(cal, lim, ms);
  return tables::PlotCurvesSvg(cal, lim, *mtpa, mtpv.ok() ? &*mtpv : nullptr);
}

}  // namespace fluxcal::pipeline
