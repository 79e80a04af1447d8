#include "pipeline/local_fit.h"

#include "fitting/plot.h"
#include "identification/identify.h"

namespace fluxcal::pipeline {

absl::Status CheckModelName(const std::string& name) { return fit::ParseModelName(name).status(); }

absl::Status CheckSetFacts(const io::RecordingSet& set, const StatedFacts& stated) {
  fit::FitData probe = fit::FitDataFromRecording(set, {});
  // The points' recorded temperatures, which identification would carry
  // into the data (--magnet-reference-c is refused for data that record
  // one): stand-ins holding nothing else, checked and dropped.
  for (const auto& p : set.manifest.points) {
    if (!p.temperature_c) continue;
    fit::InductanceObservation o;
    o.temperature_c = p.temperature_c;
    probe.inductances.push_back(o);
  }
  return ApplyStatedFacts(stated, FactSource::kRecordingSet, &probe);
}

fit::FitData FitDataFromHfResults(const std::vector<io::HfResultRow>& rows) {
  return fit::FitDataFromHfRows(nullptr, rows);
}

fit::FitData FitDataFromFluxMap(const io::FluxMap& map, int pole_pairs, double psi_std_wb, const std::string& serial) {
  fit::FitData data = fit::FitDataFromFluxMap(map, pole_pairs, psi_std_wb);
  data.serial = serial;
  return data;
}

absl::StatusOr<fit::Calibration> FitCalibration(const fit::FitData& data, const std::string& model) {
  fit::FitOptions options;
  options.model = model;
  return fit::Fit(data, options);
}

std::string FitPlotSvg(const fit::Calibration& cal, const fit::FitData& data) { return fit::PlotFitSvg(cal, data); }

}  // namespace fluxcal::pipeline
