#include "pipeline/facts.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "io/csv.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {
namespace {

const char* SourceName(FactSource s) {
  switch (s) {
    case FactSource::kRecordingSet: return "the set's manifest";
    case FactSource::kHfResults: return "hf_results.csv";
    case FactSource::kFluxMap: return "the flux map";
  }
  return "the data";
}

bool Same(double a, double b) { return std::abs(a - b) <= 1e-9 * std::max(std::abs(a), std::abs(b)); }

}  // namespace

absl::Status ApplyStatedFacts(const StatedFacts& stated, FactSource source, fit::FitData* d,
                              std::vector<std::string>* notes) {
  // Range checks first: a bad value is a usage error whatever the source says.
  if (stated.serial && !io::IsValidSerial(*stated.serial)) {
    return absl::InvalidArgumentError(absl::StrCat("flag --serial: '", io::Printable(*stated.serial),
                                                   "' is not 1 to 64 characters of A-Z a-z 0-9 - _ ."));
  }
  if (stated.pole_pairs && (*stated.pole_pairs < 1 || *stated.pole_pairs > 100)) {
    return absl::InvalidArgumentError(absl::StrCat("flag --pole-pairs: expected an integer 1..100, got ",
                                                   *stated.pole_pairs));
  }
  struct Flag {
    const char* flag;
    const std::optional<double>& value;
    bool zero_ok;
  };
  for (const Flag& f : {Flag{"--psi-pm-wb", stated.psi_pm_wb, true}, Flag{"--rs-ohm", stated.rs_ohm, true},
                        Flag{"--udc-v", stated.udc_v, false}}) {
    if (f.value && (!std::isfinite(*f.value) || *f.value < 0 || (!f.zero_ok && *f.value == 0))) {
      return absl::InvalidArgumentError(absl::StrFormat("flag %s: must be a %s number, got %g", f.flag,
                                                        f.zero_ok ? "non-negative" : "positive", *f.value));
    }
  }
  if (const auto& a = stated.psi_pm_temp_coeff_per_k;
      a && !(std::isfinite(*a) && *a >= io::kMinPsiPmTempCoeffPerK && *a <= io::kMaxPsiPmTempCoeffPerK)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "flag --magnet-temp-coeff-per-k: must be in [%g, %g] per kelvin (a relative change, not %%/K: NdFeB is "
        "about -0.0011), got %g", io::kMinPsiPmTempCoeffPerK, io::kMaxPsiPmTempCoeffPerK, *a));
  }
  if (const auto& t = stated.magnet_reference_c; t && !(std::isfinite(*t) && *t >= -60 && *t <= 250)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("flag --magnet-reference-c: must be a magnet temperature in -60 .. 250 degC, got %g", *t));
  }
  const std::string from = SourceName(source);
  auto note = [&](const std::string& what) {
    if (notes != nullptr) notes->push_back(what);
  };
  auto conflict = [&](const char* flag, const std::string& flag_value, const char* field, const std::string& value) {
    return absl::InvalidArgumentError(absl::StrCat("flag ", flag, ": ", flag_value, " differs from ", from, "'s ",
                                                   field, " ", value, "; a flag may only state what ", from,
                                                   " does not (correct the source, or leave the flag out)"));
  };
  // Serial.
  if (stated.serial) {
    if (!d->serial.empty() && d->serial != *stated.serial) {
      return conflict("--serial", "'" + *stated.serial + "'", "serial", "'" + d->serial + "'");
    }
    if (d->serial.empty()) note(absl::StrCat("serial ", *stated.serial, " from --serial"));
    d->serial = *stated.serial;
  }
  // Pole pairs.
  if (stated.pole_pairs) {
    if (d->pole_pairs != 0 && d->pole_pairs != *stated.pole_pairs) {
      return conflict("--pole-pairs", absl::StrCat(*stated.pole_pairs), "pole_pairs", absl::StrCat(d->pole_pairs));
    }
    if (d->pole_pairs == 0) note(absl::StrCat("pole pairs ", *stated.pole_pairs, " from --pole-pairs"));
    d->pole_pairs = *stated.pole_pairs;
  }
  // The optional quantities.
  struct Quantity {
    const char* flag;
    const char* field;
    const std::optional<double>& stated;
    std::optional<double>* have;
  };
  for (const Quantity& q : {Quantity{"--psi-pm-wb", "psi_pm_wb", stated.psi_pm_wb, &d->psi_pm_prior_wb},
                            Quantity{"--rs-ohm", "rs_ohm", stated.rs_ohm, &d->rs_ohm},
                            Quantity{"--udc-v", "udc_v", stated.udc_v, &d->udc_v},
                            Quantity{"--magnet-temp-coeff-per-k", "psi_pm_temp_coeff_per_k",
                                     stated.psi_pm_temp_coeff_per_k, &d->psi_pm_temp_coeff_per_k}}) {
    if (!q.stated) continue;
    if (*q.have && !Same(**q.have, *q.stated)) {
      return conflict(q.flag, absl::StrFormat("%g", *q.stated), q.field, absl::StrFormat("%g", **q.have));
    }
    if (!*q.have) note(absl::StrFormat("%s %g from %s", q.field, *q.stated, q.flag));
    *q.have = *q.stated;
  }
  // The magnet temperature of data that record none.
  if (stated.magnet_reference_c) {
    size_t recorded = 0;
    for (const auto& o : d->inductances) recorded += o.temperature_c.has_value();
    for (const auto& o : d->steady_state) recorded += o.temperature_c.has_value();
    for (const auto& o : d->fluxes) recorded += o.temperature_c.has_value();
    if (recorded > 0) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "flag --magnet-reference-c: %g degC, but %zu observations of %s record their own temperature_c (the "
          "calibration's magnet reference is their mean); a flag may only state what %s does not (leave the "
          "flag out)", *stated.magnet_reference_c, recorded, from, from));
    }
    for (auto& o : d->inductances) o.temperature_c = stated.magnet_reference_c;
    for (auto& o : d->steady_state) o.temperature_c = stated.magnet_reference_c;
    for (auto& o : d->fluxes) o.temperature_c = stated.magnet_reference_c;
    note(absl::StrFormat("magnet reference temperature %g degC from --magnet-reference-c", *stated.magnet_reference_c));
  }
  // What a calibration cannot do without.
  std::vector<std::string> missing;
  if (d->serial.empty()) missing.push_back("--serial S (the motor's serial)");
  if (d->pole_pairs == 0) missing.push_back("--pole-pairs P (torque and speed depend on them)");
  const bool psi_observable = !d->steady_state.empty() || !d->fluxes.empty();
  if (!d->psi_pm_prior_wb && !psi_observable) {
    missing.push_back(
        "--psi-pm-wb WB (the nominal magnet flux: psi_pm is not observable from differential inductances alone, "
        "which are slopes d psi / d i and say nothing of psi at zero current)");
  }
  if (!missing.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(from, " does not state what the calibration needs; give ",
                                                   absl::StrJoin(missing, ", ")));
  }
  return absl::OkStatus();
}

}  // namespace fluxcal::pipeline
