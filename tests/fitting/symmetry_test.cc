// The machine's symmetry (psi_d even, psi_q odd in iq) as the fit's default
// (docs/fitting.md, "Symmetry"): which iq halves the data measured, what a
// calibration says on the other half (measured / by symmetry /
// extrapolated), its JSON, and the validity of a point whose differential
// inductance is not positive definite. Data: the public bench set and its
// measured map (data/real, both halves measured there), the twin (truth on
// both halves).
#include <cmath>
#include <cstdio>
#include <string>

#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "fitting/surface.h"
#include "gtest/gtest.h"
#include "identification/identify.h"
#include "io/flux_map.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "simulation/twin.h"
#include "tests/fitting/spline_families.h"

namespace fluxcal::fit {
namespace {

const std::string kReal = std::string(FLUXCAL_SOURCE_DIR) + "/data/real";

FitData PublicBench() {
  auto set = io::ReadRecordingSet(kReal + "/baldor_eol");
  EXPECT_TRUE(set.ok()) << set.status();
  return FitDataFromRecording(*set, {});
}

const io::FluxMap& MeasuredMap() {
  static const io::FluxMap* m = [] {
    auto map = io::ReadFluxMapCsv(kReal + "/baldor_fluxmap_measured.csv");
    EXPECT_TRUE(map.ok()) << map.status();
    return new io::FluxMap(map.ok() ? *map : io::FluxMap{});
  }();
  return *m;
}

// RMS flux error against the measured map's nodes in id [id_lo, id_hi], iq
// [iq_lo, iq_hi], relative to the largest |psi| there (the figure of
// `fluxcal compare`).
double MapRms(const Calibration& cal, double id_lo, double id_hi, double iq_lo, double iq_hi, int* nodes = nullptr) {
  const auto& m = MeasuredMap();
  double sum = 0, scale = 0;
  int n = 0;
  for (size_t i = 0; i < m.id_a.size(); ++i) {
    for (size_t j = 0; j < m.iq_a.size(); ++j) {
      const double id = m.id_a[i], iq = m.iq_a[j];
      if (id < id_lo || id > id_hi || iq < iq_lo || iq > iq_hi) continue;
      const auto f = cal.Flux(id, iq);
      sum += std::pow(f.psi_d_wb - m.psi_d_wb[i][j], 2) + std::pow(f.psi_q_wb - m.psi_q_wb[i][j], 2);
      scale = std::max(scale, std::hypot(m.psi_d_wb[i][j], m.psi_q_wb[i][j]));
      ++n;
    }
  }
  if (nodes != nullptr) *nodes = n;
  return n > 0 ? std::sqrt(sum / n) / scale : 1.0;
}

bool Listed(const Calibration& cal, const std::string& family) {
  for (const auto& c : cal.summary.candidates) {
    if (c.rfind(family + " ", 0) == 0) return true;
  }
  return false;
}

// The repro: the bench measured iq >= 0 only. The fit is symmetric,
// says so, and the braking half it states by symmetry matches the machine's
// measured braking half (RMS over id -18..0 A, iq -24..0 A: 62 % with the
// asymmetric model fitted to one half, which auto chose before); the
// motoring half stays within the 0.5 % it was (0.291 % before).
TEST(Symmetry, OneSidedBenchFitsTheMachinesSymmetry) {
  auto cal = Fit(PublicBench());
  ASSERT_TRUE(cal.ok()) << cal.status();
  EXPECT_TRUE(cal->family().SymmetricInIq()) << cal->family().Name();
  EXPECT_FALSE(Listed(*cal, "smooth-asym")) << "one half measured: no asymmetric candidate";
  EXPECT_EQ(cal->iq_halves(), IqHalves::kPositive);
  EXPECT_EQ(cal->iq_signed_min_a(), 0.0);
  EXPECT_EQ(cal->iq_signed_max_a(), 24.0);
  int n_motoring = 0, n_braking = 0;
  const double motoring = MapRms(*cal, -18, 0, 0, 24, &n_motoring);
  const double braking = MapRms(*cal, -18, 0, -24, 0, &n_braking);
  ASSERT_EQ(n_motoring, 130);
  ASSERT_EQ(n_braking, 130);
  std::printf("public bench set: %s, flux RMS against the measured map: motoring %.3f %%, braking (by symmetry) "
              "%.3f %%\n", cal->family().Name().c_str(), 100 * motoring, 100 * braking);
  EXPECT_LT(motoring, 0.005);
  EXPECT_LT(braking, 0.005);
  // The query of the repro: (-10, -12) A lies on the mirrored half.
  const auto p = cal->Predict(-10, -12);
  EXPECT_EQ(p.region, Region::kBySymmetry);
  EXPECT_FALSE(p.extrapolated);
  EXPECT_TRUE(p.valid) << p.invalid_reason;
  EXPECT_GT(p.ldd_h, 0.0);
  const auto m = cal->Predict(-10, 12);
  EXPECT_EQ(m.region, Region::kMeasured);
  EXPECT_NEAR(p.ldd_h, m.ldd_h, 1e-12 * m.ldd_h) << "the mirrored half is the measured one's image";
  EXPECT_NEAR(p.psi_q_wb, -m.psi_q_wb, 1e-12);
  EXPECT_EQ(cal->Predict(-10, 30).region, Region::kExtrapolated);
  EXPECT_EQ(cal->Predict(-10, -30).region, Region::kExtrapolated);
  EXPECT_EQ(cal->Predict(-30, -12).region, Region::kExtrapolated);
}

// Asked for by name on one half, the asymmetric model is fitted, and its
// other half is extrapolated, not "by symmetry"; where it is not positive
// definite there (Ldd -9.5 mH at (-10, -12) A in the repro) the point is
// not valid.
TEST(Symmetry, AsymmetricModelByNameOnOneHalfFlagsTheOther) {
  FitOptions o;
  o.model = "smooth-asym";
  auto cal = Fit(PublicBench(), o);
  ASSERT_TRUE(cal.ok()) << cal.status();
  ASSERT_EQ(cal->family().Name(), "smooth-asym");
  EXPECT_FALSE(cal->family().SymmetricInIq());
  const auto p = cal->Predict(-10, -12);
  EXPECT_EQ(p.region, Region::kExtrapolated);
  EXPECT_TRUE(p.extrapolated);
  EXPECT_EQ(p.valid, p.ldd_h > 0 && p.lqq_h > 0 && p.ldd_h * p.lqq_h > p.ldq_h * p.ldq_h);
  EXPECT_EQ(cal->Predict(-10, 12).region, Region::kMeasured);
  EXPECT_NE(cal->IqRegionText().find("extrapolated"), std::string::npos) << cal->IqRegionText();
}

// Both halves measured (the public map itself, all 567 nodes): the
// asymmetric model is a candidate again and everything is measured.
TEST(Symmetry, BothHalvesMeasuredAdmitTheAsymmetricModel) {
  auto cal = Fit(FitDataFromFluxMap(MeasuredMap(), 2));
  ASSERT_TRUE(cal.ok()) << cal.status();
  EXPECT_EQ(cal->iq_halves(), IqHalves::kBoth);
  EXPECT_TRUE(Listed(*cal, "smooth-asym"));
  EXPECT_EQ(cal->Predict(-10, -12).region, Region::kMeasured);
  EXPECT_EQ(cal->Predict(-10, 12).region, Region::kMeasured);
  const double all = MapRms(*cal, -20, 20, -26, 26);
  std::printf("measured map, both halves: %s, flux RMS %.3f %%\n", cal->family().Name().c_str(), 100 * all);
  EXPECT_LT(all, 0.005);
}

// What makes a half measured (fit.cc, MeasuredIqOf): a stray row or two on
// the other side, or points within the zero band, do not; a real second
// half does.
TEST(Symmetry, AHalfIsMeasuredByItsShareAndSpan) {
  FitData d = PublicBench();
  FitData stray = d;
  for (double id : {-18.0, -4.0}) stray.steady_state.push_back({id, -20.0, 400.0, -150.0, -80.0, std::nullopt});
  auto a = Fit(stray);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->iq_halves(), IqHalves::kPositive) << "two rows at -20 A of 47 observations";
  EXPECT_FALSE(Listed(*a, "smooth-asym"));
  EXPECT_EQ(a->iq_signed_min_a(), 0.0);
  FitData noise = d;
  for (auto& o : noise.inductances) {
    if (o.iq_a == 0) o.iq_a = -0.3;   // a zero set point read back slightly negative (5 % band: 1.2 A)
  }
  auto b = Fit(noise);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->iq_halves(), IqHalves::kPositive);
  EXPECT_EQ(b->iq_signed_min_a(), 0.0);
  EXPECT_EQ(b->Predict(-10, -0.3).region, Region::kMeasured);
  // The bench's HF points mirrored (iq -> -iq, Ldq -> -Ldq, as the
  // machine's symmetry has them): both halves measured.
  FitData both = d;
  for (const auto& o : d.inductances) {
    if (o.iq_a <= 0) continue;
    InductanceObservation m = o;
    m.iq_a = -o.iq_a;
    if (m.ldq_h) m.ldq_h = -*m.ldq_h;
    both.inductances.push_back(m);
  }
  auto c = Fit(both);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->iq_halves(), IqHalves::kBoth);
  EXPECT_EQ(c->iq_signed_min_a(), -24.0);
  EXPECT_TRUE(Listed(*c, "smooth-asym"));
}

// The twin (analytic motor with cross saturation, default plan: id
// -100..0 A, iq 0..100 A): the fit is symmetric and the half it states by
// symmetry is the motor's own within 0.5 % (flux relative to the largest
// |psi|, inductance RMS), because the motor is symmetric.
TEST(Symmetry, TwinOneHalfMirrorsTheTruth) {
  sim::TwinConfig cfg;
  cfg.seed = 23;
  cfg.sensors.noise_a = 0.08;
  cfg.motor.sat.g_cross_h = 3e-5;
  auto r = sim::Simulate(cfg, sim::DefaultPlan());
  ASSERT_TRUE(r.ok()) << r.status();
  auto ids = ident::IdentifySet(r->set, {});
  ASSERT_TRUE(ids.ok()) << ids.status();
  auto cal = Fit(FitDataFromRecording(r->set, *ids));
  ASSERT_TRUE(cal.ok()) << cal.status();
  EXPECT_TRUE(cal->family().SymmetricInIq()) << cal->family().Name();
  EXPECT_EQ(cal->iq_halves(), IqHalves::kPositive);
  const sim::AnalyticMotor truth(cfg.motor);
  double e_psi = 0, scale = 0, e_l = 0;
  int n = 0;
  for (double id = -100; id <= 0; id += 10) {
    for (double iq = -100; iq <= -10; iq += 10) {
      const auto p = cal->Predict(id, iq);
      EXPECT_EQ(p.region, Region::kBySymmetry) << id << ", " << iq;
      EXPECT_TRUE(p.valid) << p.invalid_reason;
      const auto f = truth.Flux(id, iq);
      const auto l = truth.Inductance(id, iq);
      e_psi = std::max(e_psi, std::hypot(p.psi_d_wb - f.psi_d_wb, p.psi_q_wb - f.psi_q_wb));
      scale = std::max(scale, std::hypot(f.psi_d_wb, f.psi_q_wb));
      e_l += std::pow(p.ldd_h / l.ldd_h - 1, 2) + std::pow(p.lqq_h / l.lqq_h - 1, 2);
      n += 2;
    }
  }
  std::printf("twin, mirrored half: %s, worst flux %.3f %%, inductance RMS %.3f %%\n", cal->family().Name().c_str(),
              100 * e_psi / scale, 100 * std::sqrt(e_l / n));
  EXPECT_LT(e_psi / scale, 0.005);
  EXPECT_LT(std::sqrt(e_l / n), 0.005);
}

// A negative differential inductance is never reported as valid: a model
// whose Ldd is negative everywhere (the analytic family with Ld0 < 0, which
// the fit's bounds never produce) is not valid at any point, measured or
// not, and says why.
TEST(Symmetry, NonPositiveDefiniteIsNeverValid) {
  Family f;
  f.kind = Family::kAnalytic;
  Calibration cal("NEG", f, {0.01, -1e-4, 3e-4, 400, 300, 0, 100}, {}, 4, 0.01, -100, 0, 0, 100);
  cal.SetMeasuredIq(IqHalves::kPositive, 0, 100);
  for (double iq : {50.0, -50.0, 500.0}) {
    const auto p = cal.Predict(-50, iq);
    EXPECT_FALSE(p.valid) << iq;
    EXPECT_NE(p.invalid_reason.find("ldd_h"), std::string::npos) << p.invalid_reason;
  }
  EXPECT_EQ(cal.Predict(-50, 50).region, Region::kMeasured);
  EXPECT_EQ(cal.Predict(-50, -50).region, Region::kBySymmetry);
  EXPECT_EQ(cal.Predict(-50, 500).region, Region::kExtrapolated);
  EXPECT_FALSE(cal.PhysicalOver(1.0));
}

// The halves in the calibration JSON: written, read back exactly; a file
// written before them (no `iq_halves`) loads as before, its |iq| box
// measured on both halves; a bad value is refused naming the field.
TEST(Symmetry, CalibrationJsonCarriesTheHalvesCompatibly) {
  auto cal = Fit(PublicBench());
  ASSERT_TRUE(cal.ok()) << cal.status();
  const nlohmann::json j = cal->ToJson();
  EXPECT_EQ(j["region"]["iq_halves"], "positive");
  auto back = Calibration::FromJson(j);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->ToJson().dump(), j.dump());
  EXPECT_EQ(back->RegionOf(-10, -12), Region::kBySymmetry);
  nlohmann::json old = j;
  old["region"].erase("iq_halves");
  old["region"].erase("iq_signed_min_a");
  old["region"].erase("iq_signed_max_a");
  auto legacy = Calibration::FromJson(old);
  ASSERT_TRUE(legacy.ok()) << legacy.status();
  EXPECT_EQ(legacy->iq_halves(), IqHalves::kUnknown);
  EXPECT_EQ(legacy->RegionOf(-10, -12), Region::kMeasured) << "as before: the |iq| box mirrored";
  EXPECT_EQ(legacy->RegionOf(-10, 12), Region::kMeasured);
  EXPECT_EQ(legacy->RegionOf(-10, -30), Region::kExtrapolated);
  EXPECT_FALSE(legacy->ToJson()["region"].contains("iq_halves"));
  nlohmann::json bad = j;
  bad["region"]["iq_halves"] = "upper";
  auto refused = Calibration::FromJson(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("region.iq_halves"), std::string::npos) << refused.status();
  bad = j;
  bad["region"]["iq_signed_min_a"] = -24.0;   // "positive" with a negative extent
  EXPECT_FALSE(Calibration::FromJson(bad).ok());
}

// A calibration written with the folded symmetric layout (before the
// mirrored one) still loads and evaluates as it did.
TEST(Symmetry, FoldedSmoothCalibrationStillLoads) {
  const Family f = SymmetricSmoothSpline(8, -19, 1, 16, -25, 25, /*mirrored=*/false);
  std::vector<double> p(f.NumParams(), 0.0);
  p[0] = 0.44;
  for (size_t k = 1; k < p.size(); ++k) p[k] = 0.01 * std::sin(0.7 * k);
  Calibration cal("FOLDED", f, p, {}, 2, 3.6, -18, 0, 0, 24);
  const nlohmann::json j = cal.ToJson();
  EXPECT_FALSE(j["spline_knots"].contains("mirrored"));
  auto back = Calibration::FromJson(j);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_FALSE(back->family().spline.mirrored);
  for (double iq : {-20.0, 0.0, 7.0}) {
    EXPECT_EQ(back->Flux(-9, iq).psi_q_wb, cal.Flux(-9, iq).psi_q_wb);
    EXPECT_EQ(back->Inductance(-9, iq).ldd_h, cal.Inductance(-9, iq).ldd_h);
  }
}

// The surfaces' fast evaluator (SurfaceEvaluator, what Calibration::Flux,
// Inductance and every replay call) gives the templated family's values on
// every layout: the symmetric mirrored spline of one-sided data, the
// asymmetric one, the folded spline<R>, a polynomial; both signs of iq,
// and SurfaceAt, the values and gradients the diagnosis refit uses;
// inside the knot span and beyond it (the Taylor continuation).
TEST(Symmetry, SurfaceEvaluatorIsTheFamily) {
  const FitData data = PublicBench();
  for (const char* model : {"smooth", "smooth-asym", "spline", "poly3"}) {
    FitOptions o;
    o.model = model;
    auto cal = Fit(data, o);
    ASSERT_TRUE(cal.ok()) << model << ": " << cal.status();
    const Family& f = cal->family();
    const SurfaceEvaluator ev(f, cal->params());
    for (double id : {-30.0, -17.0, -6.5, 0.0, 3.0}) {
      for (double iq : {-40.0, -12.0, -0.3, 0.0, 0.7, 9.0, 23.0, 35.0}) {
        double want[5], got[5];
        FamilyFlux(f, id, iq, cal->params().data(), &want[0], &want[1]);
        FamilyInductance(f, id, iq, cal->params().data(), &want[2], &want[3], &want[4]);
        ev.Eval(id, iq, &got[0], &got[1], &got[2], &got[3], &got[4]);
        // SurfaceAt (the diagnosis refit's values and parameter
        // gradients): the same values, and, the spline and polynomial
        // families being linear in their parameters, each value the
        // gradient's sum over them.
        const SurfacePoint sp = SurfaceAt(f, cal->params().data(), id, iq);
        double lin[5] = {0, 0, 0, 0, 0};
        for (const auto& [idx, g] : sp.grad) {
          for (int k = 0; k < 5; ++k) lin[k] += g[k] * cal->params()[idx];
        }
        for (int k = 0; k < 5; ++k) {
          const double tol = 1e-12 + 1e-10 * std::abs(want[k]);
          EXPECT_NEAR(got[k], want[k], tol) << f.Name() << " value " << k << " at id " << id << " A, iq " << iq << " A";
          EXPECT_NEAR(sp.value[k], want[k], tol) << f.Name() << " SurfaceAt " << k << " at " << id << ", " << iq;
          EXPECT_NEAR(lin[k], want[k], tol) << f.Name() << " SurfaceAt gradient " << k << " at " << id << ", " << iq;
        }
      }
    }
  }
}

}  // namespace
}  // namespace fluxcal::fit
