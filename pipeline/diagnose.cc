#include "pipeline/diagnose.h"

#include "simulation/effects.h"

namespace fluxcal::pipeline {

absl::StatusOr<diag::Table1Result> DiagnoseTable1File(const std::string& path) {
  auto rows = diag::ReadTable1(path);
  if (!rows.ok()) return rows.status();
  return diag::DiagnoseTable1(*rows);
}

bool IsKnownEffect(const std::string& name) { return sim::FindEffect(name) != nullptr; }

absl::StatusOr<diag::DiagnosisReport> DiagnoseSet(const io::RecordingSet& set,
                                                  const std::set<std::string>& excluded_effects) {
  diag::DiagnoseOptions options;
  options.excluded_effects = excluded_effects;
  return diag::Diagnose(set, options);
}

std::array<std::string, 3> DiagnosisFigures(const diag::DiagnosisReport& report) {
  return {diag::ResidualMapSvg(report, false), diag::ResidualMapSvg(report, true), diag::SpectrumSvg(report)};
}

absl::StatusOr<nlohmann::json> DiagnosedCalibrationJson(const diag::DiagnosisReport& report) {
  auto cal = diag::DiagnosedCalibration(report);
  if (!cal.ok()) return cal.status();
  return diag::MarkedCalibrationJson(report, *cal);
}

nlohmann::json DiagnosisJson(const diag::DiagnosisReport& report) { return diag::ToJson(report); }

std::string DiagnosisText(const diag::DiagnosisReport& report) { return diag::ToText(report); }

}  // namespace fluxcal::pipeline
