// Flux maps out of a calibration and back: a calibration fitted to a map
// sampled from the twin's analytic motor (cross saturation) reproduces the
// motor, its own sampled map compares to zero error, and its inverse map
// i(psi) returns currents whose flux is the grid's flux.
#include <cmath>
#include <random>
#include <sstream>

#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "io/flux_map.h"
#include "simulation/trait_motor.h"
#include "simulation/twin.h"
#include "tables/flux_map_export.h"
#include "tests/tables/twin_limits.h"

namespace fluxcal::tables {
namespace {

// The motor's map over the motoring quadrant an EOL bench covers, 17 x 17
// nodes (10 A steps), and the calibration `fit --map` makes of it (model
// auto: the analytic family, which holds the motor exactly) and the spline
// family's (which must approximate it).
struct MapCase {
  io::FluxMap map;
  fit::Calibration cal, spline;
};
const MapCase& Case() {
  static const MapCase* c = [] {
    auto* c = new MapCase;
    const auto& motor = SaturatedTwin();
    auto map = SampleFluxMap(motor, {-160, 0, 17}, {0, 160, 17});
    EXPECT_TRUE(map.ok()) << map.status();
    c->map = *map;
    fit::FitData d = fit::FitDataFromFluxMap(c->map, motor.params().pole_pairs);
    d.serial = "MAP-TWIN-1";
    auto cal = fit::Fit(d);
    EXPECT_TRUE(cal.ok()) << cal.status();
    c->cal = *cal;
    fit::FitOptions o;
    o.model = "spline";
    auto spline = fit::Fit(d, o);
    EXPECT_TRUE(spline.ok()) << spline.status();
    c->spline = *spline;
    return c;
  }();
  return *c;
}

TEST(FluxMapExport, FitFromMapReproducesTheMotor) {
  const auto& c = Case();
  const auto& motor = SaturatedTwin();
  fit::FitData d = fit::FitDataFromFluxMap(c.map, 4);
  ASSERT_EQ(d.fluxes.size(), 289u);
  ASSERT_TRUE(d.psi_pm_prior_wb.has_value());
  EXPECT_EQ(*d.psi_pm_prior_wb, motor.Flux(0, 0).psi_d_wb);
  double scale = 0;
  for (const auto& p : c.map.Points()) scale = std::max(scale, std::hypot(p.psi_d_wb, p.psi_q_wb));
  EXPECT_DOUBLE_EQ(d.fluxes[0].psi_std_wb, 0.002 * scale);
  EXPECT_EQ(c.cal.id_min_a(), -160.0);
  EXPECT_EQ(c.cal.iq_max_a(), 160.0);

  // At the nodes (what `compare` reports) and between them (a 0.5 A offset
  // grid the fit never saw): RMS flux error relative to the largest |psi|.
  auto between = SampleFluxMap(motor, {-159.5, -0.5, 32}, {0.5, 159.5, 32});
  ASSERT_TRUE(between.ok());
  for (const fit::Calibration* cal : {&c.cal, &c.spline}) {
    auto at_nodes = CompareWithFluxMap(*cal, c.map, MeasuredRegion(*cal));
    ASSERT_TRUE(at_nodes.ok()) << at_nodes.status();
    EXPECT_EQ(at_nodes->nodes, 289);
    auto off = CompareWithFluxMap(*cal, *between, MeasuredRegion(*cal));
    ASSERT_TRUE(off.ok());
    std::printf("fit --map of the analytic motor: %s, RMS %.4f %% at nodes, %.4f %% between, max %.4f %%\n",
                cal->family().Name().c_str(), 100 * at_nodes->rms_relative, 100 * off->rms_relative,
                100 * off->max_relative);
    EXPECT_LT(at_nodes->rms_relative, 0.005) << cal->family().Name() << ": RMS flux error at the nodes / max |psi|";
    EXPECT_LT(off->rms_relative, 0.005) << cal->family().Name() << ": RMS flux error between the nodes / max |psi|";
  }
  EXPECT_EQ(c.spline.family().kind, fit::Family::kSpline);
}

TEST(FluxMapExport, CalibrationAgainstItsOwnMapIsExact) {
  const auto& cal = Case().cal;
  LinearAxis id, iq;
  DefaultCurrentGrid(cal, &id, &iq);
  EXPECT_EQ(id.n, 21);
  EXPECT_EQ(iq.n, 21);
  auto sampled = SampleCalibration(cal, id, iq);
  ASSERT_TRUE(sampled.ok()) << sampled.status();
  EXPECT_EQ(sampled->extrapolated, 0);
  EXPECT_EQ(sampled->map.id_a.front(), cal.id_min_a());
  EXPECT_EQ(sampled->map.id_a.back(), cal.id_max_a());
  // Through the CSV text, as `map export` then `compare` do.
  auto text = io::FluxMapCsv(sampled->map);
  ASSERT_TRUE(text.ok());
  auto back = io::ParseFluxMapCsv(*text, "self.csv");
  ASSERT_TRUE(back.ok()) << back.status();
  auto c = CompareWithFluxMap(cal, *back, MeasuredRegion(cal));
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->nodes, 441);
  EXPECT_LT(c->rms_relative, 1e-12);
  EXPECT_LT(c->max_relative, 1e-12);
  EXPECT_GT(c->psi_scale_wb, 0.0);

  // Beyond the region the export counts extrapolated nodes.
  auto wide = SampleCalibration(cal, {-200, 0, 5}, {0, 160, 3});
  ASSERT_TRUE(wide.ok());
  EXPECT_EQ(wide->extrapolated, 3);   // id = -200 A, every iq
  // A region holding no node is an error naming the map.
  auto none = CompareWithFluxMap(cal, *back, {100, 200, 0, 10});
  ASSERT_FALSE(none.ok());
  EXPECT_NE(std::string(none.status().message()).find("self.csv: field 'region'"), std::string::npos)
      << none.status();
}

TEST(FluxMapExport, CompareReportsPerAxisAndWorstNode) {
  const auto& c = Case();
  io::FluxMap map = c.map;
  // Perturb one node by a known flux error: it becomes the worst node with
  // exactly that error (calibration - map = -delta).
  auto base = CompareWithFluxMap(c.cal, map, MeasuredRegion(c.cal));
  ASSERT_TRUE(base.ok());
  const double delta = 0.05;
  map.psi_q_wb[3][7] += delta;
  auto r = CompareWithFluxMap(c.cal, map, MeasuredRegion(c.cal));
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->worst.id_a, map.id_a[3]);
  EXPECT_EQ(r->worst.iq_a, map.iq_a[7]);
  const auto f = c.cal.Flux(map.id_a[3], map.iq_a[7]);
  EXPECT_EQ(r->worst_error_q_wb, f.psi_q_wb - map.psi_q_wb[3][7]);
  EXPECT_EQ(r->max_wb, std::hypot(r->worst_error_d_wb, r->worst_error_q_wb));
  EXPECT_NEAR(r->rms_wb * r->rms_wb, r->rms_d_wb * r->rms_d_wb + r->rms_q_wb * r->rms_q_wb, 1e-18);
  EXPECT_NEAR(r->rms_relative, r->rms_wb / r->psi_scale_wb, 1e-15);
  // A region restricted to one node compares that node only.
  auto one = CompareWithFluxMap(c.cal, map, {map.id_a[3], map.id_a[3], map.iq_a[7], map.iq_a[7]});
  ASSERT_TRUE(one.ok());
  EXPECT_EQ(one->nodes, 1);
  EXPECT_EQ(one->rms_wb, one->max_wb);
}

TEST(FluxMapExport, InverseMapReturnsTheGridFlux) {
 for (const fit::Calibration* c : {&Case().cal, &Case().spline}) {
  const auto& cal = *c;
  LinearAxis pd, pq;
  DefaultFluxGrid(cal, &pd, &pq);
  auto inv = InvertCalibration(cal, pd, pq);
  ASSERT_TRUE(inv.ok()) << inv.status();
  ASSERT_EQ(inv->size(), 441u);
  int valid = 0;
  double worst = 0;
  for (size_t i = 0; i < inv->psi_d_wb.size(); ++i) {
    for (size_t j = 0; j < inv->psi_q_wb.size(); ++j) {
      if (!inv->valid[i][j]) {
        EXPECT_TRUE(std::isnan(inv->id_a[i][j]));
        continue;
      }
      ++valid;
      const double id = inv->id_a[i][j], iq = inv->iq_a[i][j];
      EXPECT_TRUE(cal.InMeasuredRegion(id, iq)) << id << " A, " << iq << " A";
      const auto f = cal.Flux(id, iq);
      const double e = std::hypot(f.psi_d_wb - inv->psi_d_wb[i], f.psi_q_wb - inv->psi_q_wb[j]);
      worst = std::max(worst, e);
      EXPECT_LT(e, 1e-9) << "Flux(i(psi)) - psi at psi = (" << inv->psi_d_wb[i] << ", " << inv->psi_q_wb[j]
                         << ") Wb, in Wb";
    }
  }
  // Invalid means no solution in the measured box: an unconstrained Newton
  // iteration (plain, damped by step halving, independent of the library's)
  // that converges must land outside it.
  int checked = 0;
  for (size_t i = 0; i < inv->psi_d_wb.size(); ++i) {
    for (size_t j = 0; j < inv->psi_q_wb.size(); ++j) {
      if (inv->valid[i][j]) continue;
      double id = 0.5 * (cal.id_min_a() + cal.id_max_a()), iq = 0.5 * cal.iq_max_a();
      double r = 1e300;
      for (int it = 0; it < 200 && r > 1e-12; ++it) {
        const auto f = cal.Flux(id, iq);
        const double rd = inv->psi_d_wb[i] - f.psi_d_wb, rq = inv->psi_q_wb[j] - f.psi_q_wb;
        r = std::hypot(rd, rq);
        const auto L = cal.Inductance(id, iq);
        const double det = L.ldd_h * L.lqq_h - L.ldq_h * L.ldq_h;
        if (!(det > 0)) break;
        const double sd = (L.lqq_h * rd - L.ldq_h * rq) / det, sq = (L.ldd_h * rq - L.ldq_h * rd) / det;
        for (double a = 1; a > 1e-6; a *= 0.5) {
          const auto g = cal.Flux(id + a * sd, iq + a * sq);
          if (std::hypot(inv->psi_d_wb[i] - g.psi_d_wb, inv->psi_q_wb[j] - g.psi_q_wb) < r) {
            id += a * sd;
            iq += a * sq;
            break;
          }
        }
      }
      if (r > 1e-10) continue;   // no solution anywhere it could find
      ++checked;
      const bool inside = id >= cal.id_min_a() && id <= cal.id_max_a() && std::abs(iq) >= cal.iq_min_a() &&
                          std::abs(iq) <= cal.iq_max_a();
      EXPECT_FALSE(inside) << "invalid node psi = (" << inv->psi_d_wb[i] << ", " << inv->psi_q_wb[j]
                           << ") Wb has a solution in the measured box: " << id << " A, " << iq << " A";
    }
  }
  std::printf("inverse map (%s): %d of 441 nodes valid, worst |Flux(i(psi)) - psi| %.2g Wb; "
              "%d invalid nodes solved outside the region\n",
              cal.family().Name().c_str(), valid, worst, checked);
  EXPECT_EQ(valid, inv->valid_nodes);
  // The flux range's corners lie outside the region's curved image, its
  // middle inside: a real share is valid, not all.
  EXPECT_GT(valid, 441 / 3);
  EXPECT_LT(valid, 441);
 }
}

TEST(FluxMapExport, InverseIsUniqueAndRejectsFluxOutsideTheRegion) {
 for (const fit::Calibration* c : {&Case().cal, &Case().spline}) {
  const auto& cal = *c;
  // Currents in the region -> their flux -> the inverse at exactly that
  // flux (1 x 1 grid) gives the same currents back (the inverse is unique
  // where the inductance is positive definite).
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uid(-155, -5), uiq(5, 155);
  for (int k = 0; k < 25; ++k) {
    const double id = uid(rng), iq = uiq(rng);
    const auto f = cal.Flux(id, iq);
    auto inv = InvertCalibration(cal, {f.psi_d_wb, f.psi_d_wb, 1}, {f.psi_q_wb, f.psi_q_wb, 1});
    ASSERT_TRUE(inv.ok());
    ASSERT_TRUE(inv->valid[0][0]) << id << " A, " << iq << " A";
    EXPECT_NEAR(inv->id_a[0][0], id, 1e-6) << "id in A";
    EXPECT_NEAR(inv->iq_a[0][0], iq, 1e-6) << "iq in A";
  }
  // Negative torque side: psi_q < 0 maps to iq < 0 by symmetry.
  {
    const auto f = cal.Flux(-60, -80);
    auto inv = InvertCalibration(cal, {f.psi_d_wb, f.psi_d_wb, 1}, {f.psi_q_wb, f.psi_q_wb, 1});
    ASSERT_TRUE(inv.ok());
    ASSERT_TRUE(inv->valid[0][0]);
    EXPECT_NEAR(inv->iq_a[0][0], -80, 1e-6);
  }
  // Flux beyond anything the region reaches: invalid, with empty CSV cells.
  const double far = 10 * cal.psi_pm_wb();
  auto inv = InvertCalibration(cal, {far, far, 1}, {0, 0, 1});
  ASSERT_TRUE(inv.ok());
  EXPECT_FALSE(inv->valid[0][0]);
  EXPECT_EQ(inv->valid_nodes, 0);
  const std::string csv = InverseFluxMapCsv(*inv);
  std::istringstream in(csv);
  std::string header, row;
  std::getline(in, header);
  std::getline(in, row);
  EXPECT_EQ(header, "psi_d_Vs,psi_q_Vs,id_A,iq_A,valid");
  EXPECT_EQ(row.substr(row.size() - 4), ",,,0") << row;
 }
}

// A calibration that is not positive definite everywhere: the trait motor
// whose Ldd is negative near zero current, on a 6 x 6 bench grid (exact
// inductances, the point at (0, 0) reads non-positive, so Fit exempts its
// cells from the positive-definite check) with three flux nodes. The
// inverse still returns a map, and every node it calls valid is solved.
TEST(FluxMapExport, InverseOfAMapThatFallsNearZeroCurrent) {
  sim::MotorTraits t;
  for (const auto& m : sim::RealLikeMotors(300)) {
    if (m.name == "negative-slope") t = m;
  }
  ASSERT_EQ(t.name, "negative-slope");
  const sim::TraitMotor motor(t);
  fit::FitData d;
  d.serial = "NEG-SLOPE-1";
  d.pole_pairs = 4;   // the trait motors state none; nothing here uses torque or speed
  for (double id : {-300.0, -225.0, -165.0, -135.0, -60.0, 0.0}) {
    for (double iq : {0.0, 51.0, 126.0, 174.0, 249.0, 300.0}) {
      const auto L = motor.Inductance(id, iq);
      d.inductances.push_back({id, iq, L.ldd_h, L.lqq_h, L.ldq_h, 0, 0, 0, {}, {}});
    }
  }
  for (double id : {-300.0, -165.0, -60.0}) {
    const auto f = motor.Flux(id, 150);
    d.fluxes.push_back({id, 150, f.psi_d_wb, f.psi_q_wb, 1e-4});
  }
  ASSERT_LT(d.inductances[30].ldd_h, 0) << "the map no longer falls at (0, 0)";
  auto cal = fit::Fit(d);
  ASSERT_TRUE(cal.ok()) << cal.status();
  ASSERT_FALSE(cal->PhysicalOver(1.0)) << "the case this test is for: not positive definite everywhere";
  LinearAxis pd, pq;
  DefaultFluxGrid(*cal, &pd, &pq);
  auto inv = InvertCalibration(*cal, pd, pq);
  ASSERT_TRUE(inv.ok()) << inv.status();
  EXPECT_GT(inv->valid_nodes, 441 / 3);
  for (size_t i = 0; i < inv->psi_d_wb.size(); ++i) {
    for (size_t j = 0; j < inv->psi_q_wb.size(); ++j) {
      if (!inv->valid[i][j]) continue;
      const auto f = cal->Flux(inv->id_a[i][j], inv->iq_a[i][j]);
      EXPECT_LT(std::hypot(f.psi_d_wb - inv->psi_d_wb[i], f.psi_q_wb - inv->psi_q_wb[j]), 1e-9);
    }
  }
  std::printf("inverse of a map falling near zero current: %d of 441 nodes valid\n", inv->valid_nodes);
}

TEST(FluxMapExport, GridsAreChecked) {
  const auto& cal = Case().cal;
  const auto& motor = SaturatedTwin();
  auto e = SampleFluxMap(motor, {0, -10, 5}, {0, 10, 5});
  ASSERT_FALSE(e.ok());
  EXPECT_NE(std::string(e.status().message()).find("field 'grid id': max must exceed min"), std::string::npos)
      << e.status();
  EXPECT_FALSE(SampleFluxMap(motor, {0, 10, 0}, {0, 10, 5}).ok());
  EXPECT_FALSE(SampleFluxMap(motor, {0, 10, 5}, {0, 10, kMaxFluxMapAxisNodes + 1}).ok());
  EXPECT_FALSE(SampleFluxMap(motor, {0, INFINITY, 5}, {0, 10, 5}).ok());
  auto ie = InvertCalibration(cal, {0.1, 0.2, 3}, {0.1, 0.1, 2});
  ASSERT_FALSE(ie.ok());
  EXPECT_NE(std::string(ie.status().message()).find("field 'psi grid psi_q'"), std::string::npos) << ie.status();
  // One-node axes are allowed, and axis ends are exact.
  EXPECT_EQ((LinearAxis{-3, -3, 1}.Values()), std::vector<double>{-3});
  const auto v = LinearAxis{-0.1, 0.7, 9}.Values();
  EXPECT_EQ(v.front(), -0.1);
  EXPECT_EQ(v.back(), 0.7);
}

}  // namespace
}  // namespace fluxcal::tables
