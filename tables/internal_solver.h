// The operating-point solver's steps that BuildTable calls beyond the
// public SolveLeastCurrent / MaxTorqueNm (internal to tables/, not
// installed; defined in solver.cc).
#ifndef FLUXCAL_TABLES_INTERNAL_SOLVER_H_
#define FLUXCAL_TABLES_INTERNAL_SOLVER_H_

#include <limits>
#include <optional>
#include <vector>

#include "simulation/magnetic_model.h"
#include "tables/tables.h"

namespace fluxcal::tables::internal {

// The locus points of one torque request that every speed of a
// field-weakening row asks for again: its MTPA point and its end at
// -i_max. A locus point depends on the request and id only (the solve is
// deterministic), so the row keeps them; TrySolve looks them up by exact id.
struct RowLoci {
  double t = std::numeric_limits<double>::quiet_NaN();
  struct Point { double id; bool ok; double iq; };
  std::vector<Point> points;
};

// Least-current point for torque t under the limits; false if infeasible.
// `mtpa_id` (optional): the least-current id of this torque without a
// voltage limit, when already known (it does not depend on speed).
// `row` (optional): the kept locus points of this request (RowLoci).
bool TrySolve(const sim::MagneticModel& m, const MachineLimits& lim, double t, double we,
              OperatingPoint* op, const double* mtpa_id = nullptr, RowLoci* row = nullptr);

// As SolveLeastCurrent, with the limit torque at this speed already known.
// `clamp` (optional): the clamped point of this speed and torque sign, once
// computed; it depends on nothing else, so a field-weakening column
// computes it once for all the requests beyond its limit torque.
OperatingPoint SolveWithMax(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                            double we, double tmax, const double* mtpa_id = nullptr,
                            std::optional<OperatingPoint>* clamp = nullptr, RowLoci* row = nullptr);

}  // namespace fluxcal::tables::internal

#endif  // FLUXCAL_TABLES_INTERNAL_SOLVER_H_
