// Fitting a serial's stored runs into a new calibration version, the
// verdict it gets, and the checks on what a fit request may ask.
#include "pipeline/pipeline.h"

#include <cmath>
#include <optional>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "pipeline/internal.h"
#include "pipeline/calibration_codec.h"

namespace fluxcal::pipeline {

std::string Verdict(const fit::Calibration& cal, std::optional<double> nominal, size_t points, size_t unreliable,
                    const FitTolerances& tol) {
  // Facts first: without them no other check means anything.
  if (cal.pole_pairs() < 1) return "fail: pole pairs unknown";
  if (!nominal) nominal = cal.psi_pm_nominal_wb();
  if (!nominal) {
    return "fail: nominal psi_pm unknown (no motor.psi_pm_wb in the manifest or from the station, no "
           "--psi-pm-wb): the fitted magnet flux cannot be judged";
  }
  const double nominal_psi_pm_wb = *nominal;
  if (!cal.summary.usable) return "fail: fit did not converge";
  if (cal.summary.rms_relative > tol.max_rms_relative) {
    return absl::StrFormat("fail: fit residual %.2f %% above %.2f %%", 100 * cal.summary.rms_relative,
                           100 * tol.max_rms_relative);
  }
  // A map fit (flux nodes, no inductances) is judged by its flux error over
  // the map's nodes, against the same tolerance.
  if (cal.summary.flux_nodes > 0 && !(cal.summary.flux_rms_relative <= tol.max_rms_relative)) {
    return absl::StrFormat("fail: flux error against the map %.2f %% above %.2f %%",
                           100 * cal.summary.flux_rms_relative, 100 * tol.max_rms_relative);
  }
  if (nominal_psi_pm_wb > 0 && std::abs(cal.psi_pm_wb() / nominal_psi_pm_wb - 1) > tol.psi_pm_tolerance_relative) {
    return absl::StrFormat("fail: psi_pm %.5g Wb deviates %.1f %% from nominal", cal.psi_pm_wb(),
                           100 * (cal.psi_pm_wb() / nominal_psi_pm_wb - 1));
  }
  if (unreliable * 2 > points) {
    // Points near a phase-current zero crossing are flagged by design (the
    // paper's Sec. 3.3); only a majority of unreliable points fails a motor.
    return absl::StrFormat("fail: %zu of %zu points flagged unreliable", unreliable, points);
  }
  return "pass";
}

namespace internal {

storage::CalibrationRow NewCalibrationRow(const std::string& serial, const storage::MotorRow& motor, int64_t run_id,
                                          const fit::Calibration& cal, size_t points, size_t unreliable,
                                          const FitTolerances& tol) {
  storage::CalibrationRow row;
  row.serial = serial;
  row.run_id = run_id;
  row.model = cal.family().Name();
  row.psi_pm_wb = cal.psi_pm_wb();
  row.rms_relative = cal.summary.rms_relative;
  row.verdict = Verdict(cal, motor.psi_pm_wb > 0 ? std::optional<double>(motor.psi_pm_wb) : std::nullopt, points,
                        unreliable, tol);
  return row;
}

}  // namespace internal

absl::StatusOr<storage::CalibrationRow> FitSerial(storage::Store& store, const std::string& serial,
                                                  const std::string& model, const FitTolerances& tol,
                                                  const storage::AuditContext* audit, const CancelledFn& cancelled) {
  auto motor = store.GetMotor(serial);
  if (!motor.ok()) return motor.status();
  int64_t run_id = 0;
  auto pts = store.LatestRunPoints(serial, &run_id);
  if (!pts.ok()) return pts.status();
  size_t unreliable = 0;
  for (const auto& p : *pts) unreliable += p.reliable ? 0 : 1;
  // A run that carries its raw recording is fitted from the set, through
  // FitDataFromSet as `fluxcal fit SET` does: the steady-state rows and the
  // drive data then constrain the surfaces here as they do locally. From
  // the stored points alone psi_d is pinned only by the magnet-flux prior,
  // and its standard error came out an order of magnitude larger than the
  // local fit's for the same set.
  auto recording_sha = internal::RecordingShaOfRun(store, serial, run_id);
  if (!recording_sha.ok() && recording_sha.status().code() != absl::StatusCode::kNotFound) {
    return recording_sha.status();
  }
  fit::FitData d;
  if (recording_sha.ok()) {
    auto set = LoadStoredRecording(store, *recording_sha);
    if (!set.ok()) return set.status();
    ident::IdentifyOptions idopt;
    idopt.cancelled = cancelled;
    auto fd = FitDataFromSet(*set, idopt);
    if (!fd.ok()) return fd.status();
    d = std::move(*fd);
  } else {
    d = FitDataFromPoints(*motor, *pts);
  }
  d.serial = serial;
  fit::FitOptions fo;
  fo.model = model.empty() ? "auto" : model;
  fo.cancelled = cancelled;
  auto cal = fit::Fit(d, fo);
  if (!cal.ok()) return cal.status();
  // The last chance to stop: after this the version is stored whole.
  if (cancelled && cancelled()) return absl::CancelledError("fit: cancelled by the caller before storing");
  storage::CalibrationRow row =
      internal::NewCalibrationRow(serial, *motor, run_id, *cal, pts->size(), unreliable, tol);
  // Stored as the binary model (pipeline/calibration_codec.h); the JSON is
  // its view (StoredRowView).
  row.model_pb = EncodeCalibration(*cal);
  // An audit row without its own detail says what was stored.
  storage::AuditContext fit_audit;
  if (audit != nullptr) {
    fit_audit = *audit;
    if (!fit_audit.detail) {
      fit_audit.detail = [model = row.model, verdict = row.verdict](int64_t version, bool) {
        return absl::StrCat("version ", version, " (", model, "): ", verdict);
      };
    }
  }
  auto version = store.AddCalibration(row, audit != nullptr ? &fit_audit : nullptr);
  if (!version.ok()) return version.status();
  return StoredRowView(store, serial, *version);
}

absl::StatusOr<FitTolerances> RequestedTolerances(double max_rms_relative, double psi_pm_tolerance_relative) {
  FitTolerances tol;
  if (max_rms_relative < 0 || !std::isfinite(max_rms_relative) || psi_pm_tolerance_relative < 0 ||
      !std::isfinite(psi_pm_tolerance_relative)) {
    return absl::InvalidArgumentError("max_rms_relative, psi_pm_tolerance_relative: must be >= 0");
  }
  if (max_rms_relative > tol.max_rms_relative || psi_pm_tolerance_relative > tol.psi_pm_tolerance_relative) {
    return absl::InvalidArgumentError(
        absl::StrFormat("max_rms_relative, psi_pm_tolerance_relative: may only tighten the server policy (%g, %g)",
                        tol.max_rms_relative, tol.psi_pm_tolerance_relative));
  }
  if (max_rms_relative > 0) tol.max_rms_relative = max_rms_relative;
  if (psi_pm_tolerance_relative > 0) tol.psi_pm_tolerance_relative = psi_pm_tolerance_relative;
  return tol;
}

absl::Status CheckDistinctOperatingPoints(const std::vector<IdentifiedPoint>& points) {
  std::set<std::pair<double, double>> distinct;
  for (const auto& r : points) distinct.insert({r.id_a, r.iq_a});
  if (!points.empty() && static_cast<int>(distinct.size()) < kMinDistinctOperatingPoints) {
    return absl::InvalidArgumentError(absl::StrCat(
        "points: ", distinct.size(), " distinct operating points (id_a, iq_a); a calibration needs at least ",
        kMinDistinctOperatingPoints, "; nothing stored"));
  }
  return absl::OkStatus();
}

}  // namespace fluxcal::pipeline
