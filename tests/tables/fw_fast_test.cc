// The fast solves of the field-weakening table (tables/fast_solve.cc and
// solver.cc: FwNewton for cells and clamped points, MtpaNewton for a row's
// MTPA point, CornerLimit and MtpvLimit for limit torques, each
// warm-started and checked) against the robust reference solve they
// replace: on the public bench set's calibration and on the twin's motor
// past its MTPV onset, every cell of the fw table equals the robust solve's
// (the same flags, values within 1e-6), and a fast solve started where it
// would settle on the wrong root is refused.
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "identification/identify.h"
#include "io/recording_set.h"
#include "physics/speed.h"
#include "tables/export_rule.h"
#include "tables/internal_solver.h"
#include "tables/tables.h"
#include "tests/tables/twin_limits.h"

namespace fluxcal::tables {
namespace {

const std::string kReal = FLUXCAL_SOURCE_DIR "/data/real";

// `fluxcal fit data/real/baldor_eol`: the calibration of the EOL bench.
fit::Calibration BenchCalibration() {
  auto set = io::ReadRecordingSet(kReal + "/baldor_eol");
  EXPECT_TRUE(set.ok()) << set.status();
  auto ids = ident::IdentifySet(*set, {});
  EXPECT_TRUE(ids.ok()) << ids.status();
  auto cal = fit::Fit(fit::FitDataFromRecording(*set, *ids), {});
  EXPECT_TRUE(cal.ok()) << cal.status();
  return *cal;
}

// Each cell of a fw table (the fast paths: BuildTable) against the robust
// solve: SolveWithMax without a row (TrySolve's regula falsi over locus
// solves, its clamped point from the MTPA point on) at the limit torque
// MaxTorqueNm gives (the direct maximisation with its checks, no Newton),
// from the MTPA point TrySolve finds (scan and golden section). The flags
// must be the same and the currents agree within 1e-6 of their size (the
// golden section resolves a flat minimum to ~1e-7). Both kinds of fast
// cell must have been compared: more than `min_each` on the voltage limit
// (FwNewton) and more than `min_each` clamped.
void ExpectCellsAsTheRobustSolve(const sim::MagneticModel& m, const Table& t, int min_each) {
  int voltage_limited = 0, clamped = 0;
  const MachineLimits& lim = t.limits;
  const auto& tq = t.axes[0].values;
  const auto& rpm = t.axes[1].values;
  for (size_t i = 0; i < tq.size(); ++i) {
    const double s = tq[i] < 0 ? -1.0 : 1.0;
    OperatingPoint mtpa;
    const bool have_mtpa = internal::TrySolve(m, lim, tq[i], 0.0, &mtpa);
    for (size_t j = 0; j < rpm.size(); ++j) {
      const double we = physics::RpmToElectricalRadS(rpm[j], lim.pole_pairs);
      const double tlim = MaxTorqueNm(m, lim, we, s);
      const OperatingPoint ref = internal::SolveWithMax(m, lim, tq[i], we, tlim, have_mtpa ? &mtpa.id_a : nullptr);
      const size_t cell = i * rpm.size() + j;
      const double id = t.outputs[0].values[cell], iq = t.outputs[1].values[cell];
      ASSERT_EQ(static_cast<bool>(t.clamped[cell]), ref.clamped) << tq[i] << " N m at " << rpm[j] << " rpm";
      EXPECT_NEAR(id, ref.id_a, 1e-6 * std::max(1.0, std::abs(ref.id_a))) << tq[i] << " N m at " << rpm[j] << " rpm";
      EXPECT_NEAR(iq, ref.iq_a, 1e-6 * std::max(1.0, std::abs(ref.iq_a))) << tq[i] << " N m at " << rpm[j] << " rpm";
      clamped += ref.clamped;
      voltage_limited += !ref.clamped && VoltageV(m, lim, id, iq, we) > lim.UMaxV() * (1 - 1e-6);
    }
  }
  EXPECT_GT(voltage_limited, min_each);
  EXPECT_GT(clamped, min_each);
}

// The bench calibration's table as `fluxcal export --table fw` builds it:
// limit torques at corners of the limits, clamped points there.
TEST(FastFieldWeakening, EveryCellOfTheBenchTableAsTheRobustSolve) {
  const fit::Calibration cal = BenchCalibration();
  TableSpec spec;
  spec.kind = "fw";
  auto built = BuildExportTable(cal, spec, {});
  ASSERT_TRUE(built.ok()) << built.status();
  // Clamped cells at corners of the limits on this bench.
  ExpectCellsAsTheRobustSolve(cal, built->table, 200);
}

// The twin's saturated motor well past its MTPV onset: limit torques at
// the MTPV point (MtpvLimit), clamped points there (the robust solve).
TEST(FastFieldWeakening, EveryCellPastTheMtpvOnsetAsTheRobustSolve) {
  const sim::AnalyticMotor& m = SaturatedTwin();
  TableSpec spec = GridSpec("fw", 41, 37);
  spec.speed_max_rpm = 9000;
  auto t = BuildTable(m, TwinLimits(), spec);
  ASSERT_TRUE(t.ok()) << t.status();
  ExpectCellsAsTheRobustSolve(m, *t, 100);
}

// The guard: along a constant-torque locus whose end at -i_max violates the
// voltage limit, |u| = u_max twice, on either side of the locus' MTPV point;
// the least-current point is the root on the MTPA side. Started next to the
// other root, the Newton converges there, and the checks must refuse it;
// wherever a start is accepted, the answer is the robust solve's.
TEST(FastFieldWeakening, RefusesTheRootBeyondTheMtpvPoint) {
  const sim::AnalyticMotor& m = SaturatedTwin();
  const MachineLimits lim = TwinLimits();
  // A request and speed with two crossings inside the current limit.
  bool found = false;
  for (double rpm = 3000; rpm <= 9000 && !found; rpm += 250) {
    const double we = physics::RpmToElectricalRadS(rpm, lim.pole_pairs);
    for (double t = 2; t <= 40 && !found; t += 2) {
      OperatingPoint ref;
      if (!internal::TrySolve(m, lim, t, we, &ref)) continue;   // beyond the limit torque
      if (VoltageV(m, lim, ref.id_a, ref.iq_a, we) < lim.UMaxV() * (1 - 1e-6)) continue;   // MTPA cell
      // The locus point at id = -i_max (T(-i_max, iq) = t by bisection).
      double iq_end = 0.0;
      {
        double lo = 0.0, hi = 4 * lim.i_max_a;
        for (int k = 0; k < 200; ++k) {
          const double mid = 0.5 * (lo + hi);
          (TorqueNm(m, lim.pole_pairs, -lim.i_max_a, mid, lim.temperature_c) < t ? lo : hi) = mid;
        }
        iq_end = 0.5 * (lo + hi);
      }
      if (VoltageV(m, lim, -lim.i_max_a, iq_end, we) <= lim.UMaxV()) continue;   // one crossing only
      found = true;
      int refused = 0, accepted = 0;
      // Starts along the locus' far end (beyond the MTPV point) and near
      // the MTPA point.
      for (double f = 0.0; f <= 1.0; f += 0.05) {
        const double id0 = -lim.i_max_a + f * (lim.i_max_a + ref.id_a);
        double lo = 0.0, hi = 4 * lim.i_max_a;
        for (int k = 0; k < 200; ++k) {
          const double mid = 0.5 * (lo + hi);
          (TorqueNm(m, lim.pole_pairs, id0, mid, lim.temperature_c) < t ? lo : hi) = mid;
        }
        double id, iq;
        if (internal::FwNewton(m, lim, t, we, 1.0, id0, 0.5 * (lo + hi), 0.0, &id, &iq)) {
          ++accepted;
          EXPECT_NEAR(id, ref.id_a, 1e-6 * std::abs(ref.id_a)) << "start id " << id0 << ", " << t << " N m, " << rpm;
          EXPECT_NEAR(iq, ref.iq_a, 1e-6 * std::abs(ref.iq_a)) << "start id " << id0 << ", " << t << " N m, " << rpm;
        } else {
          ++refused;
        }
      }
      EXPECT_GT(refused, 0) << t << " N m at " << rpm << " rpm: no start settled on the far root";
      EXPECT_GT(accepted, 0) << t << " N m at " << rpm << " rpm";
    }
  }
  ASSERT_TRUE(found) << "no request with two crossings of the voltage limit inside the current limit";
}

// The limit torques of the fw table (LimitTorques: the standstill limit
// below base speed, Newton limits above it, each checked by the warm
// feasibility search) against MaxTorqueNm's (the direct maximisation,
// checked by the cold search) at every speed of the table, both signs, on
// the bench calibration (corners of the limits) and on the twin motor past
// its MTPV onset (MTPV points): the same to 1e-8.
TEST(FastFieldWeakening, LimitTorquesAsMaxTorqueNm) {
  const fit::Calibration cal = BenchCalibration();
  auto rule = BuildExportTable(cal, TableSpec{}, {});
  ASSERT_TRUE(rule.ok()) << rule.status();
  const sim::AnalyticMotor& twin = SaturatedTwin();
  const std::vector<std::pair<const sim::MagneticModel*, MachineLimits>> cases = {{&cal, rule->table.limits},
                                                                                   {&twin, TwinLimits()}};
  for (const auto& [m, lim] : cases) {
    std::vector<double> we;
    for (double rpm = 0; rpm <= 9000; rpm += 250) we.push_back(physics::RpmToElectricalRadS(rpm, lim.pole_pairs));
    int above_base = 0;
    for (double sign : {1.0, -1.0}) {
      const std::vector<internal::LimitTorque> fast = internal::LimitTorques(*m, lim, we, sign, true);
      ASSERT_EQ(fast.size(), we.size());
      for (size_t j = 0; j < we.size(); ++j) {
        const double ref = MaxTorqueNm(*m, lim, we[j], sign);
        EXPECT_NEAR(fast[j].t, ref, 1e-8 * std::max(1.0, ref)) << "sign " << sign << " at " << we[j] << " rad/s";
        above_base += fast[j].t < fast[0].t * (1 - 1e-6);
      }
    }
    EXPECT_GT(above_base, 10);   // limits above base speed were compared
  }
}

// The locus solve's options (SolveIqForTorque) change no root: from a warm
// start with the bracket grown lazily the iq is the same as with it grown
// first (where the torque is monotone in iq: within the measured region),
// the flux it returns is m.Flux at the root, and the locus' slope is the
// one the inductances give there (d iq / d id = -T_d / T_q).
TEST(FastFieldWeakening, LocusSolveOptionsChangeNoRoot) {
  const sim::AnalyticMotor& twin = SaturatedTwin();
  const MachineLimits lim = TwinLimits();
  int compared = 0;
  for (double s : {1.0, -1.0}) {
    for (double id = -lim.i_max_a; id <= 0; id += lim.i_max_a / 13) {
      for (double t : {0.5, 3.0, 10.0, 25.0}) {
        double cold;
        if (!internal::SolveIqForTorque(twin, lim, id, s * t, s, &cold)) continue;
        for (double f : {0.5, 0.9, 0.999, 1.0, 1.001, 1.2}) {
          const double guess = f * std::abs(cold);
          double eager, lazy;
          sim::FluxLinkage fl;
          double slope;
          const bool ok_eager = internal::SolveIqForTorque(twin, lim, id, s * t, s, &eager, guess);
          const bool ok_lazy = internal::SolveIqForTorque(twin, lim, id, s * t, s, &lazy, guess, &fl, true, &slope);
          ASSERT_EQ(ok_eager, ok_lazy) << id << " A, " << s * t << " N m, start " << guess;
          if (!ok_eager) continue;
          EXPECT_EQ(eager, lazy) << id << " A, " << s * t << " N m, start " << guess;
          const sim::FluxLinkage F = twin.Flux(id, lazy, lim.temperature_c);
          EXPECT_EQ(fl.psi_d_wb, F.psi_d_wb) << id << " A, " << s * t << " N m, start " << guess;
          EXPECT_EQ(fl.psi_q_wb, F.psi_q_wb);
          const sim::DifferentialInductance L = twin.Inductance(id, lazy, lim.temperature_c);
          const double t_d = 1.5 * lim.pole_pairs * (L.ldd_h * lazy - F.psi_q_wb - L.ldq_h * id);
          const double t_q = 1.5 * lim.pole_pairs * (F.psi_d_wb + L.ldq_h * lazy - L.lqq_h * id);
          EXPECT_DOUBLE_EQ(slope, -t_d / t_q) << id << " A, " << s * t << " N m";
          ++compared;
        }
      }
    }
  }
  EXPECT_GT(compared, 300);
}

}  // namespace
}  // namespace fluxcal::tables
