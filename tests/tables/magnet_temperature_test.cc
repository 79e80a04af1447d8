// Tables at a stated magnet temperature from the calibration's own
// coefficient and flux-map temperature (tables::MagnetTemperatureOf,
// docs/tables.md "Magnet temperature"): against the twin motor, whose flux
// at magnet temperature T is psi_pm(25 degC) (1 + alpha (T - 25)) on the
// same inductances (simulation/twin.h, AnalyticMotor), so the table at T
// from a fit at T_ref must be the table of a fit at T.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "simulation/twin.h"
#include "tables/export_rule.h"
#include "tables/tables.h"
#include "tests/tables/twin_limits.h"

namespace fluxcal::tables {
namespace {

// The twin motor's flux linkage at magnet temperature `temperature_c` on a
// grid (id -150..0 A, iq 0..150 A), each node recorded at that temperature,
// fitted (analytic family) with the coefficient `alpha` stated.
fit::Calibration TwinAt(double temperature_c, std::optional<double> alpha, bool recorded = true) {
  const sim::AnalyticMotor motor{sim::MotorParams{}};
  fit::FitData d;
  d.serial = "IPM-MAGNET-1";
  d.pole_pairs = sim::MotorParams().pole_pairs;
  d.rs_ohm = sim::MotorParams().rs_ohm;
  d.udc_v = sim::DriveParams().udc_v;
  d.psi_pm_temp_coeff_per_k = alpha;
  for (int a = 0; a <= 10; ++a) {
    for (int b = 0; b <= 10; ++b) {
      const double id = -150.0 + 15 * a, iq = 15.0 * b;
      const auto f = motor.Flux(id, iq, temperature_c);
      fit::FluxObservation o{id, iq, f.psi_d_wb, f.psi_q_wb, 1e-6};
      if (recorded) o.temperature_c = temperature_c;
      d.fluxes.push_back(o);
    }
  }
  d.psi_pm_prior_wb = motor.Flux(0, 0, temperature_c).psi_d_wb;
  fit::FitOptions o;
  o.model = "analytic";
  auto cal = fit::Fit(d, o);
  EXPECT_TRUE(cal.ok()) << cal.status();
  return *cal;
}

Table Mtpa(const fit::Calibration& cal, std::optional<double> magnet_temp_c) {
  TableSpec spec;
  spec.kind = "mtpa";
  ExportRequest req;
  req.i_max_a = 140;
  req.magnet_temp_c = magnet_temp_c;
  auto b = BuildExportTable(cal, spec, req);
  EXPECT_TRUE(b.ok()) << b.status();
  return b.ok() ? b->table : Table{};
}

// id and iq of `t` at torque `tq`, linear between its rows; false beyond them.
bool At(const Table& t, double tq, double* id, double* iq) {
  const auto& x = t.axes[0].values;
  for (size_t k = 1; k < x.size(); ++k) {
    if (tq >= x[k - 1] && tq <= x[k]) {
      const double w = (tq - x[k - 1]) / (x[k] - x[k - 1]);
      *id = Out(t, "id_a")[k - 1] + w * (Out(t, "id_a")[k] - Out(t, "id_a")[k - 1]);
      *iq = Out(t, "iq_a")[k - 1] + w * (Out(t, "iq_a")[k] - Out(t, "iq_a")[k - 1]);
      return true;
    }
  }
  return false;
}

// Largest |(id, iq) of `a` - (id, iq) of `b`| over the torques of `a` that
// `b` covers, A; `rows` receives how many were compared.
double WorstDifferenceA(const Table& a, const Table& b, int* rows) {
  double worst = 0;
  *rows = 0;
  for (size_t k = 0; k < a.axes[0].values.size(); ++k) {
    double id, iq;
    if (!At(b, a.axes[0].values[k], &id, &iq)) continue;
    ++*rows;
    worst = std::max(worst, std::hypot(Out(a, "id_a")[k] - id, Out(a, "iq_a")[k] - iq));
  }
  return worst;
}

// The fit at 40 degC with the twin's coefficient, exported at 120 degC, is
// the fit at 120 degC: within 0.3 % of the current limit (140 A) at every
// torque both tables hold. The table at the reference temperature is not
// (psi_pm 9.6 % higher than at 120 degC): the comparison can fail.
TEST(MagnetTemperature, TableAtTIsTheTableOfTheMachineAtT) {
  const double alpha = sim::MotorParams().psi_pm_temp_coeff_per_k;
  const fit::Calibration cold = TwinAt(40, alpha), hot = TwinAt(120, alpha);
  ASSERT_TRUE(cold.magnet_reference_c().has_value());
  EXPECT_DOUBLE_EQ(*cold.magnet_reference_c(), 40.0);
  EXPECT_EQ(cold.magnet_reference_spread_k(), 0.0);
  EXPECT_EQ(cold.psi_pm_temp_coeff_per_k(), alpha);
  const Table moved = Mtpa(cold, 120.0), truth = Mtpa(hot, std::nullopt), unmoved = Mtpa(cold, std::nullopt);
  ASSERT_TRUE(moved.magnet_temperature.has_value());
  EXPECT_DOUBLE_EQ(moved.magnet_temperature->reference_c, 40.0);
  // psi_pm(120) = psi_pm(40) (1 + alpha 80 K), the formula, to rounding.
  EXPECT_NEAR(moved.psi_pm_wb, cold.psi_pm_wb() * (1 + alpha * 80), 1e-9 * hot.psi_pm_wb());
  // The twin's alpha is relative to psi_pm at 25 degC, the formula's to
  // psi_pm at T_ref: they differ by alpha^2 (T_ref - 25 K)(T - T_ref) =
  // 0.17 % here (a datasheet's coefficient is an average over its own
  // range, no better than that).
  EXPECT_NEAR(moved.psi_pm_wb, hot.psi_pm_wb(), 0.002 * hot.psi_pm_wb())
      << "psi_pm at 120 degC from the 40 degC fit, Wb; the 120 degC fit's " << hot.psi_pm_wb();
  int rows = 0, rows_unmoved = 0;
  const double worst = WorstDifferenceA(moved, truth, &rows);
  const double worst_unmoved = WorstDifferenceA(unmoved, truth, &rows_unmoved);
  EXPECT_GE(rows, 20);
  std::printf("MTPA at 120 degC: worst |di| %.4g A moved from 40 degC, %.4g A unmoved, over %d torques\n", worst,
              worst_unmoved, rows);
  EXPECT_LE(worst, 0.003 * 140) << "A, at 120 degC from the 40 degC fit against the 120 degC fit";
  EXPECT_GE(worst_unmoved, 10 * worst) << "A: the table at the reference temperature, " << worst_unmoved
                                       << " A, should be far from the 120 degC one";
}

// Either fact missing: refused, naming exactly that one (and --magnet-temp-c
// first, the CLI's exit-code rule).
TEST(MagnetTemperature, RefusalNamesWhatIsMissing) {
  TableSpec spec;
  spec.kind = "mtpa";
  ExportRequest req;
  req.i_max_a = 140;
  req.magnet_temp_c = 100;
  const std::string coeff = "no magnet temperature coefficient", ref = "no magnet temperature of its flux map";
  struct Case {
    fit::Calibration cal;
    bool names_coeff, names_ref;
  };
  for (const Case& c : {Case{TwinAt(40, std::nullopt), true, false}, Case{TwinAt(40, -0.0012, false), false, true},
                        Case{TwinAt(40, std::nullopt, false), true, true}}) {
    auto t = BuildExportTable(c.cal, spec, req);
    ASSERT_FALSE(t.ok());
    EXPECT_EQ(t.status().code(), absl::StatusCode::kInvalidArgument);
    const std::string msg(t.status().message());
    EXPECT_EQ(msg.rfind("flag --magnet-temp-c", 0), 0u) << msg;
    EXPECT_EQ(msg.find(coeff) != std::string::npos, c.names_coeff) << msg;
    EXPECT_EQ(msg.find(ref) != std::string::npos, c.names_ref) << msg;
    if (c.names_coeff) {
      EXPECT_NE(msg.find("--magnet-temp-coeff-per-k"), std::string::npos) << msg;
    }
    if (c.names_ref) {
      EXPECT_NE(msg.find("temperature_c"), std::string::npos) << msg;
    }
  }
}

// A flux map recorded over a wide spread of temperatures (a machine warming
// during the test): the reference is their mean, the spread is stated in
// every exported format and the export's note warns.
TEST(MagnetTemperature, SpreadOfTheRecordedTemperaturesIsStated) {
  const sim::AnalyticMotor motor{sim::MotorParams{}};
  fit::FitData d;
  d.serial = "IPM-WARMING-1";
  d.pole_pairs = sim::MotorParams().pole_pairs;
  d.psi_pm_temp_coeff_per_k = -0.0011;
  for (int a = 0; a <= 10; ++a) {
    for (int b = 0; b <= 10; ++b) {
      const double id = -150.0 + 15 * a, iq = 15.0 * b, t = 30 + 3 * a;   // 30 .. 60 degC
      const auto f = motor.Flux(id, iq, t);
      fit::FluxObservation o{id, iq, f.psi_d_wb, f.psi_q_wb, 1e-6};
      o.temperature_c = t;
      d.fluxes.push_back(o);
    }
  }
  const auto ref = fit::MagnetReferenceOf(d);
  ASSERT_TRUE(ref.has_value());
  EXPECT_DOUBLE_EQ(ref->mean_c, 45.0);
  EXPECT_DOUBLE_EQ(ref->spread_k, 30.0);
  fit::FitOptions o;
  o.model = "analytic";
  auto cal = fit::Fit(d, o);
  ASSERT_TRUE(cal.ok()) << cal.status();
  ASSERT_TRUE(cal->magnet_reference_c().has_value());
  EXPECT_NEAR(*cal->magnet_reference_c(), 45.0, 1e-12);
  EXPECT_EQ(cal->magnet_reference_spread_k(), 30.0);
  EXPECT_NE(cal->MagnetTemperatureText().find("a machine warming during the test"), std::string::npos)
      << cal->MagnetTemperatureText();
  const Table t = Mtpa(*cal, 90.0);
  ASSERT_TRUE(t.magnet_temperature.has_value());
  EXPECT_NE(MagnetTemperatureNote(*t.magnet_temperature).find("warning"), std::string::npos)
      << MagnetTemperatureNote(*t.magnet_temperature);
  for (Format f : {Format::kCsv, Format::kJson, Format::kCHeader, Format::kCdfx, Format::kDcm, Format::kA2l}) {
    auto e = Export(t, f);
    ASSERT_TRUE(e.ok()) << e.status();
    const std::string text = absl::AsciiStrToLower(e->bytes);
    for (const char* name : {"magnet_temperature_c", "magnet_reference_c", "magnet_reference_spread_k",
                             "magnet_alpha_per_k", "psi_pm_scale"}) {
      EXPECT_NE(text.find(name), std::string::npos) << name << " not in format " << static_cast<int>(f);
    }
  }
  // One observation without a recorded temperature: no reference at all.
  d.fluxes[7].temperature_c.reset();
  EXPECT_FALSE(fit::MagnetReferenceOf(d).has_value());
}

}  // namespace
}  // namespace fluxcal::tables
