#include "pipeline/flux_map.h"

#include <algorithm>
#include <utility>

namespace fluxcal::pipeline {

void DefaultFluxMapGrid(const fit::Calibration& cal, bool inverse, tables::LinearAxis* a, tables::LinearAxis* b) {
  if (inverse) {
    tables::DefaultFluxGrid(cal, a, b);
  } else {
    tables::DefaultCurrentGrid(cal, a, b);
  }
}

absl::StatusOr<FluxMapExport> ExportFluxMap(const fit::Calibration& cal, const tables::LinearAxis& a,
                                            const tables::LinearAxis& b, bool inverse) {
  FluxMapExport out;
  if (inverse) {
    auto inv = tables::InvertCalibration(cal, a, b);
    if (!inv.ok()) return inv.status();
    out.csv = tables::InverseFluxMapCsv(*inv);
    out.rows = inv->size();
    out.valid_nodes = inv->valid_nodes;
    return out;
  }
  auto m = tables::SampleCalibration(cal, a, b);
  if (!m.ok()) return m.status();
  auto csv = io::FluxMapCsv(m->map);
  if (!csv.ok()) return csv.status();
  out.csv = std::move(*csv);
  out.rows = m->map.size();
  out.extrapolated = m->extrapolated;
  const auto& ids = m->map.id_a;
  const auto& iqs = m->map.iq_a;
  out.zero_current_node =
      std::find(ids.begin(), ids.end(), 0.0) != ids.end() && std::find(iqs.begin(), iqs.end(), 0.0) != iqs.end();
  return out;
}

tables::CurrentRegion MeasuredCurrentRegion(const fit::Calibration& cal) { return tables::MeasuredRegion(cal); }

absl::StatusOr<tables::FluxMapComparison> CompareWithFluxMap(const fit::Calibration& cal, const io::FluxMap& map,
                                                             const tables::CurrentRegion& region) {
  return tables::CompareWithFluxMap(cal, map, region);
}

}  // namespace fluxcal::pipeline
