#include "storage/operations.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "fitting/fit.h"
#include "nlohmann/json.hpp"

namespace fluxcal::storage {

absl::StatusOr<CalibrationRow> FitSerial(Store& store, const std::string& serial, const std::string& model,
                                         const FitTolerances& tol) {
  auto motor = store.GetMotor(serial);
  if (!motor.ok()) return motor.status();
  int64_t run_id = 0;
  auto pts = store.LatestRunPoints(serial, &run_id);
  if (!pts.ok()) return pts.status();
  fit::FitData d;
  d.serial = serial;
  d.pole_pairs = motor->pole_pairs;
  d.rs_ohm = motor->rs_ohm;
  if (motor->psi_pm_wb > 0) d.psi_pm_prior_wb = motor->psi_pm_wb;
  size_t unreliable = 0;
  for (const auto& p : *pts) {
    if (!p.reliable) ++unreliable;
    fit::InductanceObservation o;
    o.id_a = p.id_a; o.iq_a = p.iq_a; o.ldd_h = p.ld_h; o.lqq_h = p.lq_h; o.ldq_h = p.ldq_h;
    o.ldd_h_std = p.ld_h_std; o.lqq_h_std = p.lq_h_std; o.ldq_h_std = p.ldq_h_std;
    d.inductances.push_back(o);
  }
  fit::FitOptions fo;
  fo.model = model.empty() ? "auto" : model;
  auto cal = fit::Fit(d, fo);
  if (!cal.ok()) return cal.status();
  // Verdict against the station's tolerances.
  std::string verdict = "pass";
  if (!cal->summary.usable) {
    verdict = "fail: fit did not converge";
  } else if (cal->summary.rms_relative > tol.max_rms_relative) {
    verdict = absl::StrFormat("fail: fit residual %.2f %% above %.2f %%", 100 * cal->summary.rms_relative,
                              100 * tol.max_rms_relative);
  } else if (motor->psi_pm_wb > 0 && std::abs(cal->psi_pm_wb() / motor->psi_pm_wb - 1) > tol.psi_pm_tolerance_relative) {
    verdict = absl::StrFormat("fail: psi_pm %.5g Wb deviates %.1f %% from nominal", cal->psi_pm_wb(),
                              100 * (cal->psi_pm_wb() / motor->psi_pm_wb - 1));
  } else if (unreliable * 2 > pts->size()) {
    // Points near a phase-current zero crossing are flagged by design (the
    // paper's Sec. 3.3); only a majority of unreliable points fails a motor.
    verdict = absl::StrFormat("fail: %zu of %zu points flagged unreliable", unreliable, pts->size());
  }
  CalibrationRow row;
  row.serial = serial;
  row.run_id = run_id;
  row.model = cal->family().Name();
  row.psi_pm_wb = cal->psi_pm_wb();
  row.rms_relative = cal->summary.rms_relative;
  row.verdict = verdict;
  // The stored JSON carries the version it is stored under.
  auto version = store.AddCalibration([&] {
    CalibrationRow r = row;
    fit::Calibration c = *cal;
    nlohmann::json j = c.ToJson();
    r.calibration_json = j.dump();
    return r;
  }());
  if (!version.ok()) return version.status();
  return store.GetCalibration(serial, *version);
}

absl::StatusOr<fit::Calibration> LoadCalibration(Store& store, const std::string& serial, int version) {
  auto row = store.GetCalibration(serial, version);
  if (!row.ok()) return row.status();
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(row->calibration_json);
  } catch (const nlohmann::json::exception& e) {
    return absl::DataLossError(absl::StrCat("stored calibration of ", serial, " is corrupt: ", e.what()));
  }
  j["version"] = row->version;
  auto cal = fit::Calibration::FromJson(j);
  if (!cal.ok()) return cal.status();
  return cal;
}

absl::StatusOr<ExportResult> ExportTable(Store& store, const std::string& serial, int version,
                                         const tables::TableSpec& spec_in, const tables::MachineLimits& lim_in,
                                         const std::string& format) {
  auto fmt = tables::ParseFormat(format);
  if (!fmt.ok()) return fmt.status();
  auto cal = LoadCalibration(store, serial, version);
  if (!cal.ok()) return cal.status();
  tables::TableSpec spec = spec_in;
  spec.serial = serial;
  spec.calibration_version = cal->version;
  spec.model = cal->family().Name();
  tables::MachineLimits lim = lim_in;
  if (lim.i_max_a <= 0) lim.i_max_a = cal->MeasuredCurrentLimitA() > 0 ? cal->MeasuredCurrentLimitA() : 150.0;
  lim.pole_pairs = cal->pole_pairs();
  lim.rs_ohm = cal->rs_ohm();
  auto t = tables::BuildTable(*cal, lim, spec);
  if (!t.ok()) return t.status();
  auto e = tables::Export(*t, *fmt);
  if (!e.ok()) return e.status();
  ExportResult r;
  r.exported = *e;
  r.version = cal->version;
  for (auto c : t->clamped) r.clamped_cells += c;
  return r;
}

absl::StatusOr<std::vector<FleetPoint>> FleetStatistics(Store& store, const std::vector<std::pair<double, double>>& points,
                                                        double outlier_sigma) {
  auto rows = store.LatestCalibrations();
  if (!rows.ok()) return rows.status();
  std::vector<std::pair<std::string, fit::Calibration>> cals;
  for (const auto& r : *rows) {
    auto c = LoadCalibration(store, r.serial, r.version);
    if (c.ok()) cals.push_back({r.serial, std::move(*c)});
  }
  std::vector<FleetPoint> out;
  for (const auto& [id, iq] : points) {
    FleetPoint fp;
    fp.id_a = id;
    fp.iq_a = iq;
    fp.serials = static_cast<int>(cals.size());
    std::vector<fit::FluxPrediction> p;
    for (const auto& c : cals) p.push_back(c.second.Predict(id, iq));
    auto stats = [&](auto get, double* mean, double* sd) {
      double s = 0, s2 = 0;
      for (const auto& x : p) { s += get(x); s2 += get(x) * get(x); }
      const double n = std::max<size_t>(1, p.size());
      *mean = s / n;
      *sd = p.size() > 1 ? std::sqrt(std::max(0.0, (s2 - s * s / n) / (n - 1))) : 0.0;
    };
    stats([](const fit::FluxPrediction& x) { return x.ldd_h; }, &fp.ldd_mean, &fp.ldd_std);
    stats([](const fit::FluxPrediction& x) { return x.lqq_h; }, &fp.lqq_mean, &fp.lqq_std);
    stats([](const fit::FluxPrediction& x) { return x.psi_d_wb; }, &fp.psi_d_mean, &fp.psi_d_std);
    stats([](const fit::FluxPrediction& x) { return x.torque_nm; }, &fp.torque_mean, &fp.torque_std);
    // Outliers: any quantity more than outlier_sigma standard deviations from
    // the fleet mean (leave-one-out would be better for tiny fleets).
    for (size_t k = 0; k < p.size(); ++k) {
      auto z = [&](double v, double m, double s) { return s > 0 ? std::abs(v - m) / s : 0.0; };
      if (z(p[k].ldd_h, fp.ldd_mean, fp.ldd_std) > outlier_sigma || z(p[k].lqq_h, fp.lqq_mean, fp.lqq_std) > outlier_sigma ||
          z(p[k].torque_nm, fp.torque_mean, fp.torque_std) > outlier_sigma) {
        fp.outliers.push_back(cals[k].first);
      }
    }
    out.push_back(fp);
  }
  return out;
}

}  // namespace fluxcal::storage
