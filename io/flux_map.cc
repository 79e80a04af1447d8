// Flux maps: the conventions' names, the applied convention in words, a
// map's nodes, its validation, and writing it as CSV. Reading one is
// flux_map_parse.cc (the CSV) and flux_map_conform.cc (into fluxcal's
// convention, with the plausibility checks).
#include "io/flux_map.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"

namespace fluxcal::io {

const char* Name(FluxMapAxes axes) {
  switch (axes) {
    case FluxMapAxes::kAuto: return "auto";
    case FluxMapAxes::kFluxcal: return "fluxcal";
    case FluxMapAxes::kMotulator: return "motulator";
    default: return "syre";
  }
}

const char* Name(AmplitudeScaling scaling) {
  switch (scaling) {
    case AmplitudeScaling::kPeak: return "peak";
    case AmplitudeScaling::kRms: return "rms";
    default: return "power-invariant";
  }
}

const char* Name(FluxUnit unit) {
  switch (unit) {
    case FluxUnit::kFromHeader: return "header";
    case FluxUnit::kWb: return "Wb";
    case FluxUnit::kVs: return "Vs";
    case FluxUnit::kMWb: return "mWb";
    default: return "mVs";
  }
}

std::optional<FluxMapAxes> FluxMapAxesFromName(std::string_view name) {
  for (auto a : {FluxMapAxes::kAuto, FluxMapAxes::kFluxcal, FluxMapAxes::kMotulator, FluxMapAxes::kSyre}) {
    if (name == Name(a)) return a;
  }
  return std::nullopt;
}

std::optional<AmplitudeScaling> AmplitudeScalingFromName(std::string_view name) {
  for (auto a : {AmplitudeScaling::kPeak, AmplitudeScaling::kRms, AmplitudeScaling::kPowerInvariant}) {
    if (name == Name(a)) return a;
  }
  return std::nullopt;
}

std::optional<FluxUnit> FluxUnitFromName(std::string_view name) {
  for (auto u : {FluxUnit::kFromHeader, FluxUnit::kWb, FluxUnit::kVs, FluxUnit::kMWb, FluxUnit::kMVs}) {
    if (name == Name(u)) return u;
  }
  return std::nullopt;
}

std::string AppliedFluxMapConvention::Describe() const {
  std::string s = absl::StrCat("axes ", Name(axes), " (", axes_detected ? "detected" : "given",
                               detail.empty() ? "" : ": ", detail, ")");
  if (axes == FluxMapAxes::kSyre) absl::StrAppend(&s, ", converted: id = -Iq, iq = Id, psi_d = -Fq, psi_q = Fd");
  absl::StrAppend(&s, "; currents ", Name(current));
  if (current_factor != 1.0) absl::StrAppendFormat(&s, " (x %.6g)", current_factor);
  absl::StrAppend(&s, "; flux ", Name(flux), " in ", Name(flux_unit), " (", flux_unit_source, ")");
  if (flux_factor != 1.0) absl::StrAppendFormat(&s, " (x %.6g)", flux_factor);
  return s;
}


std::vector<FluxMapPoint> FluxMap::Points() const {
  std::vector<FluxMapPoint> out;
  out.reserve(size());
  for (size_t i = 0; i < id_a.size(); ++i) {
    for (size_t j = 0; j < iq_a.size(); ++j) {
      out.push_back({id_a[i], iq_a[j], psi_d_wb[i][j], psi_q_wb[i][j]});
    }
  }
  return out;
}

absl::Status ValidateFluxMap(const FluxMap& map) {
  auto axis_ok = [](const std::vector<double>& a) {
    if (a.empty()) return false;
    for (size_t k = 0; k < a.size(); ++k) {
      if (!std::isfinite(a[k]) || (k > 0 && !(a[k] > a[k - 1]))) return false;
    }
    return true;
  };
  if (!axis_ok(map.id_a)) return absl::InvalidArgumentError("field 'id_a': axis must be finite, strictly increasing, non-empty");
  if (!axis_ok(map.iq_a)) return absl::InvalidArgumentError("field 'iq_a': axis must be finite, strictly increasing, non-empty");
  for (const auto* grid : {&map.psi_d_wb, &map.psi_q_wb}) {
    const char* name = grid == &map.psi_d_wb ? "psi_d_wb" : "psi_q_wb";
    if (grid->size() != map.id_a.size()) {
      return absl::InvalidArgumentError(absl::StrCat("field '", name, "': ", grid->size(), " rows for ",
                                                     map.id_a.size(), " id values"));
    }
    for (size_t i = 0; i < grid->size(); ++i) {
      if ((*grid)[i].size() != map.iq_a.size()) {
        return absl::InvalidArgumentError(absl::StrCat("field '", name, "[", i, "]': ", (*grid)[i].size(),
                                                       " values for ", map.iq_a.size(), " iq values"));
      }
      for (size_t j = 0; j < (*grid)[i].size(); ++j) {
        if (!std::isfinite((*grid)[i][j])) {
          return absl::InvalidArgumentError(absl::StrCat("field '", name, "[", i, "][", j, "]': not finite"));
        }
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::string> FluxMapCsv(const FluxMap& map) {
  if (auto st = ValidateFluxMap(map); !st.ok()) return st;
  std::string out = "id_A,iq_A,psi_d_Vs,psi_q_Vs\n";
  out.reserve(out.size() + map.size() * 96);
  // %.17g: 17 significant digits identify every double uniquely (IEEE 754
  // binary64, DBL_DECIMAL_DIG), so the text reads back bit for bit.
  for (const auto& p : map.Points()) {
    absl::StrAppendFormat(&out, "%.17g,%.17g,%.17g,%.17g\n", p.id_a, p.iq_a, p.psi_d_wb, p.psi_q_wb);
  }
  return out;
}

absl::Status WriteFluxMapCsv(const std::string& path, const FluxMap& map) {
  auto text = FluxMapCsv(map);
  if (!text.ok()) return text.status();
  return WriteFileAtomically(path, *text);
}

}  // namespace fluxcal::io
