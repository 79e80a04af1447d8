// The store's motors: listing, history, audit trail, release and the
// version to flash, and the fleet's statistics over the latest versions.
#include "pipeline/pipeline.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace fluxcal::pipeline {

absl::StatusOr<MotorPage> ListMotorsPage(storage::Store& store, const std::string& prefix, bool only_failed,
                                         int offset, int page_size) {
  // One row more than the page: whether a next page exists, in one query.
  auto rows = store.ListMotors(prefix, only_failed, offset, page_size + 1);
  if (!rows.ok()) return rows.status();
  MotorPage page;
  if (static_cast<int>(rows->size()) > page_size) {
    rows->resize(page_size);
    page.next_offset = offset + page_size;
  }
  page.motors = std::move(*rows);
  return page;
}

absl::StatusOr<std::vector<storage::HistoryRow>> MotorHistory(storage::Store& store, const std::string& serial) {
  return store.History(serial);
}

absl::StatusOr<std::vector<storage::AuditRow>> AuditTrail(storage::Store& store, const std::string& serial) {
  return store.AuditOf(serial);
}

absl::Status ReleaseVersion(storage::Store& store, const std::string& serial, int version,
                            const std::string& released_by, const storage::AuditContext* audit) {
  return store.Release(serial, version, released_by, audit);
}

absl::StatusOr<int> FlashableVersion(storage::Store& store, const std::string& serial, int version) {
  if (version == 0) {
    auto v = store.LatestReleasedVersion(serial);
    if (!v.ok()) return v.status();
    if (*v == 0) {
      return absl::FailedPreconditionError(
          absl::StrCat("serial '", serial, "' has no released calibration (fluxcal release)"));
    }
    version = *v;
  }
  if (auto s = storage::VerifyReleasedVersion(store, serial, version); !s.ok()) return s;
  return version;
}

absl::StatusOr<std::vector<FleetPoint>> FleetStatistics(storage::Store& store,
                                                        const std::vector<std::pair<double, double>>& points,
                                                        double outlier_sigma, const CancelledFn& cancelled) {
  auto rows = store.LatestCalibrations();
  if (!rows.ok()) return rows.status();
  std::vector<std::pair<std::string, fit::Calibration>> cals;
  for (const auto& r : *rows) {
    if (cancelled && cancelled()) return absl::CancelledError("fleet statistics: cancelled by the caller");
    auto c = ParseStoredCalibration(r);
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
    stats([](const fit::FluxPrediction& x) { return x.ldd_h; }, &fp.ldd_h_mean, &fp.ldd_h_std);
    stats([](const fit::FluxPrediction& x) { return x.lqq_h; }, &fp.lqq_h_mean, &fp.lqq_h_std);
    stats([](const fit::FluxPrediction& x) { return x.psi_d_wb; }, &fp.psi_d_wb_mean, &fp.psi_d_wb_std);
    stats([](const fit::FluxPrediction& x) { return x.torque_nm; }, &fp.torque_nm_mean, &fp.torque_nm_std);
    // Outliers: any quantity more than outlier_sigma standard deviations from
    // the fleet mean (leave-one-out would be better for tiny fleets).
    for (size_t k = 0; k < p.size(); ++k) {
      auto z = [&](double v, double m, double s) { return s > 0 ? std::abs(v - m) / s : 0.0; };
      if (z(p[k].ldd_h, fp.ldd_h_mean, fp.ldd_h_std) > outlier_sigma || z(p[k].lqq_h, fp.lqq_h_mean, fp.lqq_h_std) > outlier_sigma ||
          z(p[k].torque_nm, fp.torque_nm_mean, fp.torque_nm_std) > outlier_sigma) {
        fp.outliers.push_back(cals[k].first);
      }
    }
    out.push_back(fp);
  }
  return out;
}

}  // namespace fluxcal::pipeline
