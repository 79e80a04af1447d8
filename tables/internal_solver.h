// The operating-point solver's steps that BuildTable calls beyond the
// public SolveLeastCurrent / MaxTorqueNm (internal to tables/, not
// installed; defined in solver.cc).
#ifndef FLUXCAL_TABLES_INTERNAL_SOLVER_H_
#define FLUXCAL_TABLES_INTERNAL_SOLVER_H_

#include <cmath>
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
//
// A row also carries what the fast field-weakening solve (FwNewton in
// solver.cc) needs: whether it may be tried (`fast`), the torque below
// which it may (`fast_below`: SolveWithMax keeps it away from the limit
// torque, where the robust solve decides feasibility at the edge), and the
// last voltage-limited cell of the row (`warm`), the start for the next
// speed's cell: the cells of a row move little from one speed to the next.
struct RowLoci {
  double t = std::numeric_limits<double>::quiet_NaN();
  struct Point { double id; bool ok; double iq; sim::FluxLinkage f; };   // f: the flux at (id, iq)
  std::vector<Point> points;
  bool fast = false;
  double fast_below = 0.0;
  bool warm = false;
  double warm_id = 0.0, warm_iq = 0.0;
};

// The limit torque at one speed (MaxTorqueNm) and, when the direct
// maximisation found it (`direct`), its point (id, iq): the largest torque
// of the feasible set is reached there.
struct LimitTorque {
  double t = 0.0;
  bool direct = false;
  double id = 0.0, iq = 0.0;
};

// MaxTorqueNm at each of the electrical speeds `we` (rad/s, >= 0) for the
// torque sign `sign`, with its point where the direct maximisation found it.
// Where the speed's voltage limit admits the standstill limit torque's point,
// the limit torque is the standstill one (see solver.cc). `fast`: a limit at
// a corner of the limits starts the next speed's (CornerLimit), and the
// check of every limit computed here (PassesLimitCheck) warm-starts its
// search above the limit; only within the measured current limit.
// `standstill` (optional): this sign's limit at standstill, LimitTorqueAt(m,
// lim, 0, sign), when already computed (the fw table's torque axis ends there).
std::vector<LimitTorque> LimitTorques(const sim::MagneticModel& m, const MachineLimits& lim,
                                      const std::vector<double>& we, double sign, bool fast,
                                      const LimitTorque* standstill = nullptr);

// MaxTorqueNm with its point: MaxTorqueNm(m, lim, we, sign) is its t.
LimitTorque LimitTorqueAt(const sim::MagneticModel& m, const MachineLimits& lim, double we, double sign);

// iq (sign s) on the constant-torque locus through id: T(id, iq) = t.
// Newton with a bisection safeguard; dT/diq = 1.5 p (psi_d + Ldq iq - Lqq id).
// `iq_guess_a` (> 0, magnitude): a start close to the root, e.g. the root at
// a neighbouring id; otherwise the start scales linearly from the bracket
// (the cold start). False if no bracket is found. `flux_out` (optional):
// the flux at the root, m.Flux(id, *iq_out) (from the last Newton step's
// evaluation, which is there). `lazy_bracket`: with a start given, the
// bracket's upper end is grown (a surface evaluation) only when a step
// needs it; the root is the same where the torque is monotone in iq, but
// where it is not, a root may be found where the bracket would have failed
// (for searches that any root of the locus serves). `slope_out` (optional):
// the locus' slope d iq / d id at the root (-T_d / T_q), for the next start.
bool SolveIqForTorque(const sim::MagneticModel& m, const MachineLimits& lim, double id, double t, double s,
                      double* iq_out, double iq_guess_a = 0.0, sim::FluxLinkage* flux_out = nullptr,
                      bool lazy_bracket = false, double* slope_out = nullptr);

// |u| at (id, iq) and electrical speed we from the flux there, `f`
// (m.Flux(id, iq)): VoltageV without evaluating the surface again.
inline double VoltageFromFlux(const MachineLimits& lim, double id, double iq, double we, const sim::FluxLinkage& f) {
  if (!lim.rs_ohm) return std::numeric_limits<double>::quiet_NaN();
  const double rs = *lim.rs_ohm;
  return std::hypot(rs * id - we * f.psi_q_wb, rs * iq + we * f.psi_d_wb);
}

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
// `limit` (optional): the limit torque's point at this speed (LimitTorques),
// where a row solved fast (RowLoci::fast) starts the clamped point's solve.
OperatingPoint SolveWithMax(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                            double we, double tmax, const double* mtpa_id = nullptr,
                            std::optional<OperatingPoint>* clamp = nullptr, RowLoci* row = nullptr,
                            const LimitTorque* limit = nullptr);

// The fast field-weakening solve (fast_solve.cc): the least-current point of
// torque t on the voltage limit by a 2-D Newton from (id0, iq0), accepted
// only where its checks place it at the robust solve's root (id <= id_hi,
// the MTPA point's id when known); false otherwise.
// `flux_out` (optional): the flux there, m.Flux(*id_out, *iq_out).
bool FwNewton(const sim::MagneticModel& m, const MachineLimits& lim, double t, double we, double s, double id0,
              double iq0, double id_hi, double* id_out, double* iq_out, sim::FluxLinkage* flux_out = nullptr);

// The MTPA point of torque t by a 2-D Newton from (id0, iq0) (the
// neighbouring torque row's), accepted only where its checks place it at the
// robust solve's (fast_solve.cc); false otherwise.
bool MtpaNewton(const sim::MagneticModel& m, const MachineLimits& lim, double t, double s, double id0, double iq0,
                double* id_out, double* iq_out);

// The limit torque at speed we where it is the MTPV point of the voltage
// limit, by a 2-D Newton from (id0, iq0) (the previous speed's), with its
// point; false where its checks fail (fast_solve.cc). Unchecked for being
// the largest: the caller's check (solver.cc: PassesLimitCheck).
bool MtpvLimit(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, double id0, double iq0,
               LimitTorque* out);

// One damped step of the tables' 2-D Newton solves on F = (f1, f2) with
// Jacobian [[a, b], [c, d]] (rows f1, f2; columns id, iq): the step
// -J^-1 F by Cramer's rule, shortened to `cap_a` (a start far off, not a
// converging one), added to (id, iq). False where J is singular or the step
// is not finite.
inline bool DampedNewtonStep(double a, double b, double c, double d, double f1, double f2, double cap_a, double* id,
                             double* iq) {
  const double det = a * d - b * c;
  if (!(std::abs(det) > 0) || !std::isfinite(det)) return false;
  double dd = (b * f2 - d * f1) / det, dq = (c * f1 - a * f2) / det;
  const double len = std::hypot(dd, dq);
  if (!std::isfinite(len)) return false;
  if (len > cap_a) {
    dd *= cap_a / len;
    dq *= cap_a / len;
  }
  *id += dd;
  *iq += dq;
  return true;
}

}  // namespace fluxcal::tables::internal

#endif  // FLUXCAL_TABLES_INTERNAL_SOLVER_H_
