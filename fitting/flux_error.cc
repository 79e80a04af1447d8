#include "fitting/flux_error.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace fluxcal::fit {

FluxNodeError FluxErrorOverNodes(const sim::MagneticModel& model, const std::vector<io::FluxMapPoint>& nodes) {
  FluxNodeError r;
  double sum_d = 0, sum_q = 0;
  for (size_t k = 0; k < nodes.size(); ++k) {
    const auto& p = nodes[k];
    const auto f = model.Flux(p.id_a, p.iq_a);
    const double ed = f.psi_d_wb - p.psi_d_wb, eq = f.psi_q_wb - p.psi_q_wb;
    const double e = std::hypot(ed, eq);
    sum_d += ed * ed;
    sum_q += eq * eq;
    r.psi_scale_wb = std::max(r.psi_scale_wb, std::hypot(p.psi_d_wb, p.psi_q_wb));
    if (k == 0 || e > r.max_wb) {
      r.max_wb = e;
      r.worst = k;
      r.worst_error_d_wb = ed;
      r.worst_error_q_wb = eq;
    }
  }
  r.nodes = static_cast<int>(nodes.size());
  if (nodes.empty()) return r;
  const double n = static_cast<double>(nodes.size());
  r.rms_wb = std::sqrt((sum_d + sum_q) / n);
  r.rms_d_wb = std::sqrt(sum_d / n);
  r.rms_q_wb = std::sqrt(sum_q / n);
  auto rel = [&](double x) {
    return r.psi_scale_wb > 0 ? x / r.psi_scale_wb : (x == 0 ? 0.0 : std::numeric_limits<double>::infinity());
  };
  r.rms_relative = rel(r.rms_wb);
  r.max_relative = rel(r.max_wb);
  return r;
}

}  // namespace fluxcal::fit
