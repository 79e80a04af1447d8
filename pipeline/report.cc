#include "pipeline/report.h"

#include <iterator>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "diagnosis/diagnose.h"
#include "io/sha256.h"
#include "pipeline/calibration_codec.h"
#include "pipeline/points.h"
#include "tables/tables.h"

namespace fluxcal::pipeline {

absl::StatusOr<report::Report> BuildReportPage(const report::ReportInputs& in) { return report::BuildReport(in); }
namespace {

constexpr char kDiagnosisFormat[] = "fluxcal.diagnosis.v1";

}  // namespace

void MergeStoredProvenance(int version, const std::string& created_utc, const std::string& verdict,
                           std::optional<bool> released, nlohmann::json* j) {
  (*j)["version"] = version;
  (*j)["created_utc"] = created_utc;
  if (!verdict.empty()) (*j)["verdict"] = verdict;
  if (released) (*j)["released"] = *released ? "released for flashing" : "not released";
}

void FillReportInputsFromJson(const fit::Calibration& cal, const nlohmann::json& cal_json, report::ReportInputs* in) {
  in->calibration = &cal;
  in->calibration_json = cal_json;
  in->software_version = tables::FluxcalVersion();
  if (auto v = cal_json.find("verdict"); v != cal_json.end() && v->is_string()) {
    in->verdict = v->get<std::string>();
    in->verdict_basis = "as stored with the calibration";
  } else {
    in->verdict = Verdict(cal, std::nullopt, 0, 0, FitTolerances{});
    in->verdict_basis = cal.psi_pm_nominal_wb()
                            ? "from the fit and the calibration's nominal psi_pm; give --set to also check the point flags"
                            : "from the fit; the calibration states no nominal psi_pm (give --set with a manifest that does)";
  }
  // A diagnosed calibration carries its findings (effect and parameters)
  // but not the rest of the diagnosis (mismatches, residuals): the page
  // shows what is there and says where the whole report comes from. A
  // block of another format is left out rather than failing the page.
  if (auto d = cal_json.find("diagnosis"); d != cal_json.end() && d->is_object()) {
    if (auto f = d->find("format"); f != d->end() && *f == kDiagnosisFormat) {
      nlohmann::json doc = *d;
      if (!doc.contains("serial")) doc["serial"] = cal.serial();
      in->diagnosis = std::move(doc);
      in->diagnosis_path =
          "the findings marked into this diagnosed calibration (the whole diagnosis with its mismatches and "
          "residuals: fluxcal diagnose)";
    }
  }
}

absl::Status AddRecordingSetToReport(const io::RecordingSet& set, const std::string& set_dir,
                                     const ident::IdentifyOptions& options, fit::FitData* measured,
                                     report::ReportInputs* in) {
  const fit::Calibration& cal = *in->calibration;
  if (!set.manifest.serial.empty() && set.manifest.serial != cal.serial()) {
    return absl::InvalidArgumentError(absl::StrCat(set_dir, "/manifest.json: field 'serial': '", set.manifest.serial,
                                                   "' is not the calibration's serial '", cal.serial(), "'"));
  }
  auto ids = pipeline::IdentifySet(set, options);
  if (!ids.ok()) return ids.status();
  // The set's own rows (hf_results, steady state) and the manifest's facts
  // as the fit takes them, then the points identified here.
  *measured = fit::FitDataFromRecording(set, {});
  size_t unreliable = 0;
  std::vector<fit::InductanceObservation> identified;
  for (const auto& p : ids->points) {
    if (!p.reliable) ++unreliable;
    identified.push_back(ToObservation(p));
  }
  measured->inductances.insert(measured->inductances.begin(), identified.begin(), identified.end());
  in->identified = measured;
  in->set_path = set_dir;
  if (!in->udc_v && set.manifest.drive.udc_v) {
    in->udc_v = *set.manifest.drive.udc_v;
    in->udc_source = set_dir + "/manifest.json drive.udc_v";
  }
  // The manifest's nominal psi_pm, else the calibration's (Verdict).
  in->verdict = Verdict(cal, set.manifest.motor.psi_pm_wb, measured->inductances.size(), unreliable, FitTolerances{});
  in->verdict_basis = "judged as the EOL flow does: fit, psi_pm against the manifest's nominal, point flags";
  return absl::OkStatus();
}

void AddFluxMapToReport(const io::FluxMap& map, const std::string& path, fit::FitData* measured,
                        report::ReportInputs* in) {
  const fit::FitData nodes = fit::FitDataFromFluxMap(map, in->calibration->pole_pairs());
  measured->fluxes.insert(measured->fluxes.end(), nodes.fluxes.begin(), nodes.fluxes.end());
  if (measured->pole_pairs == 0) measured->pole_pairs = in->calibration->pole_pairs();
  in->identified = measured;
  in->map_path = path;
}

namespace {

std::vector<double> Doubles(const nlohmann::json& j, const char* key) {
  std::vector<double> v;
  if (!j.is_object() || !j.contains(key) || !j[key].is_array()) return v;
  for (const auto& x : j[key]) {
    if (!x.is_number()) return {};
    v.push_back(x.get<double>());
  }
  return v;
}

}  // namespace

absl::Status AddDiagnosisOfSetToReport(const io::RecordingSet& set, const std::string& set_dir,
                                       report::ReportInputs* in) {
  auto rep = diag::Diagnose(set);
  if (!rep.ok()) return rep.status();
  in->diagnosis = diag::ToJson(*rep);
  in->diagnosis_path = absl::StrCat("run here on ", set_dir, " (fluxcal diagnose ", set_dir, ")");
  in->diagnosis_figures = {
      {diag::ResidualMapSvg(*rep, false),
       "Normalised residual |z| per standstill operating point against the nominal model, before the findings "
       "(fluxcal diagnose --plots: residual_before.svg)."},
      {diag::ResidualMapSvg(*rep, true),
       "The same after the findings: what the final model leaves unexplained (residual_after.svg)."},
      {diag::SpectrumSvg(*rep),
       "Spectrum of the waveform replay residual with the nominal and the final model (replay_spectrum.svg)."}};
  in->diagnosis_figures_note = absl::StrCat("Residual maps and spectrum: computed by this report from the recording set ",
                                            set_dir, " with fluxcal ", tables::FluxcalVersion(), "'s diagnosis.");
  return absl::OkStatus();
}

void AddDiagnosisDocumentToReport(const nlohmann::json& doc, const std::string& path, report::ReportInputs* in) {
  in->diagnosis = doc;
  in->diagnosis_path = path;
  in->diagnosis_figures.clear();
  // The document's waveform block carries the replay spectrum; drawn as
  // `fluxcal diagnose --plots` draws it. Its format is checked by the page.
  const bool ours = doc.is_object() && doc.value("format", "") == kDiagnosisFormat;
  const auto wave = ours && doc.contains("waveform") ? doc["waveform"] : nlohmann::json();
  diag::DiagnosisReport r;
  r.serial = ours ? doc.value("serial", "") : "";
  r.spectrum_hz = Doubles(wave, "spectrum_hz");
  r.spectrum_before_a = Doubles(wave, "spectrum_before_a");
  r.spectrum_after_a = Doubles(wave, "spectrum_after_a");
  if (wave.is_object()) {
    r.waveform_rms_before_a = wave.value("residual_rms_before_a", 0.0);
    r.waveform_rms_after_a = wave.value("residual_rms_after_a", 0.0);
  }
  const bool spectrum = !r.spectrum_hz.empty() && r.spectrum_hz.size() == r.spectrum_before_a.size() &&
                        r.spectrum_hz.size() == r.spectrum_after_a.size();
  if (spectrum) {
    in->diagnosis_figures.push_back(
        {diag::SpectrumSvg(r), absl::StrCat("Spectrum of the waveform replay residual with the nominal and the final "
                                            "model, from the waveform block of ", path, ".")});
  }
  in->diagnosis_figures_note = absl::StrCat(
      spectrum ? "Replay spectrum: from the document. " : "The document carries no replay spectrum. ",
      "Residual maps: not drawn: a fluxcal.diagnosis.v1 document carries no per-point residuals "
      "(fluxcal report cal.json --set DIR --diagnose runs the diagnosis here and draws them).");
}

absl::StatusOr<StoredReport> BuildStoredReport(storage::Store& store, const std::string& serial, int version,
                                               const StoredReportOptions& options, const CancelledFn& cancelled) {
  auto stopped = [&cancelled] { return cancelled && cancelled(); };
  const auto cancelled_error = [] { return absl::CancelledError("report: cancelled by the caller"); };
  auto row = store.GetCalibration(serial, version);
  if (!row.ok()) return row.status();
  auto released = store.IsReleased(serial, row->version);
  if (!released.ok()) return released.status();
  auto stored = StoredCalibrationJson(*row);
  if (!stored.ok()) return stored.status();
  nlohmann::json j = std::move(*stored);
  MergeStoredProvenance(row->version, row->created_utc, row->verdict, *released, &j);
  auto cal = fit::Calibration::FromJson(j);
  if (!cal.ok()) {
    return absl::DataLossError(
        absl::StrCat("stored calibration of ", serial, " version ", row->version, ": ", cal.status().message()));
  }
  if (stopped()) return cancelled_error();

  report::ReportInputs in;
  FillReportInputsFromJson(*cal, j, &in);
  in.calibration_path = absl::StrCat(serial, " version ", row->version, " from the service's store");
  // The store always records the creation time; the page shows that.
  in.calibration_file_mtime_utc = "unknown";
  if (options.speed_rpm > 0) in.ellipse_speed_rpm = options.speed_rpm;
  if (options.udc_v > 0) {
    in.udc_v = options.udc_v;
    in.udc_source = kUdcFromRequest;
  }   // else the calibration's, when it states one (report::BuildReport)
  StoredReport out;
  if (options.include_fleet) {
    const std::vector<std::pair<double, double>> points(std::begin(kDefaultFleetPointsA),
                                                        std::end(kDefaultFleetPointsA));
    auto fleet = FleetStatistics(store, points, kDefaultOutlierSigma, cancelled);
    if (!fleet.ok()) return fleet.status();
    in.fleet = std::move(*fleet);
    in.fleet_source =
        "FleetStatistics of the service at its default operating points (latest calibration of every serial)";
    out.fleet_included = !in.fleet.empty();
  }
  if (stopped()) return cancelled_error();
  auto page = report::BuildReport(in);
  if (!page.ok()) {
    // The request was valid; the stored calibration cannot be drawn.
    return absl::FailedPreconditionError(page.status().message());
  }
  out.page = std::move(*page);
  out.html_sha256 = io::Sha256Hex(out.page.html);
  out.serial = serial;
  out.version = row->version;
  out.verdict = in.verdict;
  return out;
}

}  // namespace fluxcal::pipeline
