// The B-spline co-energy family: the basis (partition of unity, derivatives,
// smooth continuation beyond the knots), the family's physics by
// construction (psi = grad W', L = Hessian, psi_q(id, 0) = 0,
// psi_d(0, 0) = psi_pm) for random coefficients, and fits with known truth.
#include <cmath>
#include <random>
#include <regex>
#include <set>
#include <tuple>

#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "fitting/flux_family.h"
#include "fitting/plot.h"
#include "gtest/gtest.h"
#include "identification/identify.h"
#include "nlohmann/json.hpp"
#include "simulation/flux_map.h"
#include "simulation/twin.h"
#include "tests/fitting/spline_families.h"
#include "tests/fitting/truth_error.h"

namespace fluxcal::fit {
namespace {

// Value of basis function `index` at x, from the nonzero set EvalBasis gives.
double BasisValue(double x, double lo, double hi, int spans, int index, int derivative) {
  const Basis1d b = EvalBasis(x, lo, hi, spans);
  const int r = index - b.first;
  if (r < 0 || r > kSplineDegree) return 0.0;
  return derivative == 0 ? b.v[r] : (derivative == 1 ? b.d1[r] : b.d2[r]);
}

TEST(SplineBasis, PartitionOfUnityAndDerivatives) {
  const double lo = -105, hi = 5;
  for (int spans : {1, 2, 5}) {
    const int n = spans + kSplineDegree;
    for (double x = lo; x <= hi; x += 0.37) {
      const Basis1d b = EvalBasis(x, lo, hi, spans);
      double sum = 0, sum1 = 0, sum2 = 0;
      for (int r = 0; r <= kSplineDegree; ++r) {
        EXPECT_GE(b.v[r], -1e-15);
        EXPECT_LT(b.first + r, n);
        sum += b.v[r];
        sum1 += b.d1[r];
        sum2 += b.d2[r];
      }
      EXPECT_NEAR(sum, 1.0, 1e-12) << "x " << x;   // sum B_i = 1, so its derivatives vanish
      EXPECT_NEAR(sum1, 0.0, 1e-12);
      EXPECT_NEAR(sum2, 0.0, 1e-12);
      // Derivatives against central differences, for every function.
      const double h = 1e-4;
      for (int i = 0; i < n; ++i) {
        const double fd1 = (BasisValue(x + h, lo, hi, spans, i, 0) - BasisValue(x - h, lo, hi, spans, i, 0)) / (2 * h);
        const double fd2 = (BasisValue(x + h, lo, hi, spans, i, 1) - BasisValue(x - h, lo, hi, spans, i, 1)) / (2 * h);
        EXPECT_NEAR(BasisValue(x, lo, hi, spans, i, 1), fd1, 1e-7) << "B'_" << i << " at " << x;
        EXPECT_NEAR(BasisValue(x, lo, hi, spans, i, 2), fd2, 1e-7) << "B''_" << i << " at " << x;
      }
    }
  }
}

TEST(SplineBasis, ContinuesSmoothlyBeyondTheKnots) {
  const double lo = -105, hi = 5;
  const int spans = 3, n = spans + kSplineDegree;
  for (double edge : {lo, hi}) {
    for (int i = 0; i < n; ++i) {
      for (int d = 0; d <= 2; ++d) {
        const double in = BasisValue(edge - 1e-9 * (edge == hi ? 1 : -1), lo, hi, spans, i, d);
        const double out = BasisValue(edge + 1e-9 * (edge == hi ? 1 : -1), lo, hi, spans, i, d);
        EXPECT_NEAR(in, out, 1e-8) << "basis " << i << " derivative " << d << " at " << edge;
      }
      // Beyond the edge: a quadratic (constant second derivative).
      const double out = edge == hi ? hi + 30 : lo - 30;
      EXPECT_NEAR(BasisValue(out, lo, hi, spans, i, 2), BasisValue(edge, lo, hi, spans, i, 2), 1e-12);
    }
  }
}

// At (id, iq): psi_d even and psi_q odd in iq, and L the Jacobian of psi
// by central differences of step h (reciprocal: d psi_d / d iq = d psi_q /
// d id = Ldq), each within tol.
void ExpectEvenOddAndJacobian(const Family& f, const std::vector<double>& p, double id, double iq, double h,
                              double tol) {
  auto psi = [&](double i_d, double i_q, double* d, double* q) { FamilyFlux(f, i_d, i_q, p.data(), d, q); };
  double d1, q1, dm, qm;
  psi(id, iq, &d1, &q1);
  psi(id, -iq, &dm, &qm);
  EXPECT_NEAR(dm, d1, 1e-14);
  EXPECT_NEAR(qm, -q1, 1e-14);
  double ldd, lqq, ldq;
  FamilyInductance(f, id, iq, p.data(), &ldd, &lqq, &ldq);
  double a, b, c, e;
  psi(id + h, iq, &a, &b);
  psi(id - h, iq, &c, &e);
  EXPECT_NEAR(ldd, (a - c) / (2 * h), tol) << id << ", " << iq;
  EXPECT_NEAR(ldq, (b - e) / (2 * h), tol) << id << ", " << iq;
  psi(id, iq + h, &a, &b);
  psi(id, iq - h, &c, &e);
  EXPECT_NEAR(ldq, (a - c) / (2 * h), tol) << "reciprocity at " << id << ", " << iq;
  EXPECT_NEAR(lqq, (b - e) / (2 * h), tol) << id << ", " << iq;
}

// The id values the random-coefficient tests probe: inside and beyond the
// knots, on both sides of id = 0.
constexpr double kAxisIds[] = {-150.0, -100.0, -37.0, 0.0, 6.0, 20.0};

// psi_d(0, 0) = psi_pm (parameter 0), and psi_q(id, 0) = 0 within `tol_q`
// at every id of kAxisIds.
void ExpectPsiPmAndNoPsiQOnTheIdAxis(const Family& f, const std::vector<double>& p, double tol_q) {
  double d0, q0;
  FamilyFlux(f, 0.0, 0.0, p.data(), &d0, &q0);
  EXPECT_NEAR(d0, p[0], 1e-15) << "psi_d(0, 0) = psi_pm";
  for (double id : kAxisIds) {
    double d, q;
    FamilyFlux(f, id, 0.0, p.data(), &d, &q);
    EXPECT_NEAR(q, 0.0, tol_q) << "psi_q(id, 0) = 0 at id " << id;
  }
}

// Random coefficients: whatever the fit finds, the surfaces are physical
// where the family guarantees it.
TEST(SplineFamily, ConservativeAndSymmetricByConstruction) {
  Family f;
  f.kind = Family::kSpline;
  f.spline = {3, -110, 8, 110};
  const std::vector<double> p = RandomCoefficients(f, 5);
  ExpectPsiPmAndNoPsiQOnTheIdAxis(f, p, 1e-15);
  for (double id : kAxisIds) {
    // L = d psi / d i (central differences), inside and beyond the knots.
    for (double iq : {-140.0, -60.0, 13.0, 55.0, 109.0, 130.0}) ExpectEvenOddAndJacobian(f, p, id, iq, 1e-3, 1e-8);
  }
}

// The mirrored smoothing-spline layout (the measured |iq| range, evaluated
// at |iq| with the odd part at iq = 0 removed) with random coefficients:
// psi_d(0, 0) = psi_pm, psi_d even and psi_q odd in iq, psi_q(id, 0) = 0,
// L = Jacobian of psi (reciprocal), inside and beyond the knots, and flux
// and inductance continuous across iq = 0 (W' is C2 there; only Lqq's
// slope may turn).
TEST(SplineFamily, MirroredLayoutIsConservativeEvenAndContinuous) {
  const Family f = SymmetricSmoothSpline(4, -110, 8, 6, -6, 110, /*mirrored=*/true);
  ASSERT_TRUE(f.SymmetricInIq());
  ASSERT_EQ(f.Name(), "smooth");
  const std::vector<double> p = RandomCoefficients(f, 7);
  auto psi = [&](double id, double iq, double* d, double* q) { FamilyFlux(f, id, iq, p.data(), d, q); };
  auto ind = [&](double id, double iq, double* a, double* b, double* c) { FamilyInductance(f, id, iq, p.data(), a, b, c); };
  ExpectPsiPmAndNoPsiQOnTheIdAxis(f, p, 1e-14);
  for (double id : kAxisIds) {
    // Across iq = 0: flux and inductance continuous (one-sided limits).
    double dp, qp, dm, qm, lp[3], lm[3];
    psi(id, 1e-7, &dp, &qp);
    psi(id, -1e-7, &dm, &qm);
    EXPECT_NEAR(dp, dm, 1e-9);
    EXPECT_NEAR(qp, qm, 1e-8);
    ind(id, 1e-7, &lp[0], &lp[1], &lp[2]);
    ind(id, -1e-7, &lm[0], &lm[1], &lm[2]);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(lp[c], lm[c], 1e-9) << "inductance " << c << " at id " << id;
    for (double iq : {-140.0, -60.0, -0.5, 0.7, 13.0, 55.0, 109.0, 130.0}) {
      ExpectEvenOddAndJacobian(f, p, id, iq, 1e-4, 1e-7);
    }
  }
}

// The set-up-once surfaces a Calibration evaluates (SplineSurface) give the
// family's values to the last bit, for the three layouts (folded spline<R>,
// mirrored smooth, smooth-asym), inside and beyond the knots, through
// Flux, Inductance and FluxAndInductance.
TEST(SplineFamily, CalibrationSurfacesEqualTheFamilyExactly) {
  std::vector<Family> families(3);
  for (auto& f : families) f.kind = Family::kSpline;
  families[0].spline = {3, -110, 8, 110};
  for (int k : {1, 2}) {
    SplineDomain& d = families[k].spline;
    d.spans = 4;
    d.id_lo_a = -110;
    d.id_hi_a = 8;
    d.smoothing = true;
    d.spans_q = 6;
    d.symmetric = k == 1;
    d.mirrored = k == 1;
    d.iq_lo_a = k == 1 ? -6 : -90;
    d.iq_hi_a = 110;
  }
  std::mt19937_64 rng(11);
  std::normal_distribution<double> nd(0, 1);
  for (const Family& f : families) {
    std::vector<double> p(f.NumParams());
    p[0] = 0.0114;
    for (size_t k = 1; k < p.size(); ++k) p[k] = nd(rng);
    const Calibration cal("S", f, p, {}, 4, std::nullopt, -110, 8, 0, 110);
    for (double id : {-150.0, -100.0, -37.0, 0.0, 6.0, 20.0}) {
      for (double iq : {-140.0, -60.0, -0.5, 0.0, 0.7, 13.0, 55.0, 109.0, 130.0}) {
        double d, q, ldd, lqq, ldq;
        FamilyFlux(f, id, iq, p.data(), &d, &q);
        FamilyInductance(f, id, iq, p.data(), &ldd, &lqq, &ldq);
        const auto F = cal.Flux(id, iq);
        const auto L = cal.Inductance(id, iq);
        sim::FluxLinkage F2;
        sim::DifferentialInductance L2;
        cal.FluxAndInductance(id, iq, 25.0, &F2, &L2);
        for (const auto& [x, y] : {std::pair{F.psi_d_wb, d}, {F.psi_q_wb, q}, {L.ldd_h, ldd}, {L.lqq_h, lqq},
                                   {L.ldq_h, ldq}, {F2.psi_d_wb, d}, {F2.psi_q_wb, q}, {L2.ldd_h, ldd},
                                   {L2.lqq_h, lqq}, {L2.ldq_h, ldq}}) {
          EXPECT_EQ(x, y) << f.Name() << " at " << id << ", " << iq;
        }
      }
    }
  }
}

// The analytic family's one-pass FluxAndInductance (the tables' Newton
// steps) gives Flux's and Inductance's values to the last bit, with and
// without cross saturation, beyond the saturation currents and at zero.
TEST(AnalyticFamily, FluxAndInductanceEqualFluxAndInductanceExactly) {
  Family f;
  f.kind = Family::kAnalytic;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.5, 2.0);
  for (int k = 0; k < 20; ++k) {
    sim::SaturationParams sp;
    std::vector<double> p(sim::kSaturationParams);
    sim::ToArray(sp, p.data());
    if (k > 0) {
      for (double& x : p) x *= u(rng);
      if (k % 2 == 0) p[5] = 0.0;   // no cross saturation
      if (k % 3 == 0) p[5] = 3e-5 * u(rng);
    }
    const Calibration cal("S", f, p, {}, 4, std::nullopt, -110, 8, 0, 110);
    for (double id : {-900.0, -150.0, -37.3, -1e-3, 0.0, 6.0}) {
      for (double iq : {-600.0, -60.0, -0.5, 0.0, 0.7, 55.1, 109.0, 900.0}) {
        const auto F = cal.Flux(id, iq);
        const auto L = cal.Inductance(id, iq);
        sim::FluxLinkage F2;
        sim::DifferentialInductance L2;
        cal.FluxAndInductance(id, iq, 25.0, &F2, &L2);
        for (const auto& [x, y] : {std::pair{F2.psi_d_wb, F.psi_d_wb}, {F2.psi_q_wb, F.psi_q_wb}, {L2.ldd_h, L.ldd_h},
                                   {L2.lqq_h, L.lqq_h}, {L2.ldq_h, L.ldq_h}}) {
          EXPECT_EQ(x, y) << "at " << id << ", " << iq;
        }
      }
    }
  }
}

// Fits with known truth: both twin magnetics families, spline only.
TEST(SplineFit, RecoversTruthOnBothMagneticsFamilies) {
  sim::MotorParams mp;
  mp.sat.g_cross_h = 3e-5;
  sim::AnalyticMotor source(mp);
  for (bool gridded : {false, true}) {
    sim::TwinConfig cfg;
    cfg.seed = 22;
    cfg.sensors.noise_a = 0.08;
    cfg.effects.cross_saturation = gridded ? 0.0 : 3e-5;
    if (gridded) {
      cfg.magnetics = std::make_shared<sim::GriddedFluxMap>(sim::GriddedFluxMap::FromModel(source, -160, 40, 41, 160, 33));
    }
    auto r = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(r.ok());
    auto ids = ident::IdentifySet(r->set, {});
    ASSERT_TRUE(ids.ok());
    FitOptions o;
    o.model = "spline";
    auto cal = Fit(FitDataFromRecording(r->set, *ids), o);
    ASSERT_TRUE(cal.ok()) << cal.status();
    EXPECT_EQ(cal->family().kind, Family::kSpline);
    for (const auto& t : r->truth_points) EXPECT_GT(cal->Predict(t.id_true_a, t.iq_true_a).ldd_h_std, 0.0);
    const TruthError e = AgainstTruth(*cal, r->truth_points);
    EXPECT_LT(e.inductance_rms, 0.005) << cal->family().Name()
                                       << (gridded ? " on the gridded map" : " on the analytic motor");
    EXPECT_LT(e.flux_max, 0.005) << cal->family().Name();
    // Exact JSON round trip, knots included.
    auto back = Calibration::FromJson(nlohmann::json::parse(cal->ToJson().dump()));
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_EQ(back->ToJson().dump(), cal->ToJson().dump());
    const auto a = cal->Flux(-130, 120), b = back->Flux(-130, 120);
    EXPECT_EQ(a.psi_d_wb, b.psi_d_wb);
    EXPECT_EQ(a.psi_q_wb, b.psi_q_wb);
    // The fit plot: one dot per identified point in each panel, and every
    // distinct iq (Ldd panel) and id (Lqq panel) level of the plan named in
    // a legend entry (curves lying on top of each other share one).
    const FitData data = FitDataFromRecording(r->set, *ids);
    const std::string svg = PlotFitSvg(*cal, data);
    auto count = [&](const std::string& in, const std::string& what) {
      size_t n = 0;
      for (size_t at = in.find(what); at != std::string::npos; at = in.find(what, at + 1)) ++n;
      return n;
    };
    EXPECT_EQ(svg.rfind("<svg", 0), 0u);
    EXPECT_NE(svg.find("</svg>"), std::string::npos);
    auto panel = [&](const std::string& id) {
      const size_t a = svg.find("id=\"" + id + "\"");
      return a == std::string::npos ? std::string() : svg.substr(a, svg.find("</svg>", a) - a);
    };
    std::set<long> iq_levels, id_levels;
    for (const auto& o : data.inductances) {
      iq_levels.insert(std::lround(std::abs(o.iq_a) / 10) * 10);   // plan levels, held within a few A
      id_levels.insert(std::lround(o.id_a / 10) * 10);
    }
    for (const auto& [id, levels, name] : {std::tuple{"fit-ldd", &iq_levels, "iq"}, std::tuple{"fit-lqq", &id_levels, "id"}}) {
      const std::string p = panel(id);
      ASSERT_FALSE(p.empty()) << id;
      EXPECT_EQ(count(p, "class=\"point\""), data.inductances.size()) << id;
      EXPECT_GE(count(p, "class=\"line\""), 1u) << id;
      // The legend's level lists ("iq = 0, 40 A", or "|iq| = 0 .. 160 A (6
      // levels, one curve)") add up to the plan's levels.
      size_t named = 0;
      const std::regex entry(std::string(">\\|?") + name + "\\|? = ([-0-9., ]+) A( \\((\\d+) levels, one curve\\))?<");
      for (std::sregex_iterator it(p.begin(), p.end(), entry), end; it != end; ++it) {
        named += (*it)[3].matched ? std::stoul((*it)[3]) : count((*it)[1], ",") + 1;
      }
      EXPECT_EQ(named, levels->size()) << id;
    }
    std::printf("spline fit (%s): %s, L RMS %.3f %%, worst psi %.3f %%\n", gridded ? "gridded map" : "analytic",
                cal->family().Name().c_str(), 100 * e.inductance_rms, 100 * e.flux_max);
  }
}

}  // namespace
}  // namespace fluxcal::fit
