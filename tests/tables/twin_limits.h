// The limits the table tests compute for: the twin motor's pole pairs and
// Rs, the twin drive's Udc (the test motors are the twin's analytic family)
// and a current limit of 150 A. Stated here, once: tables::MachineLimits has
// no defaults of any machine. And the twin's calibration the export tests
// start from.
#ifndef FLUXCAL_TESTS_TABLES_TWIN_LIMITS_H_
#define FLUXCAL_TESTS_TABLES_TWIN_LIMITS_H_

#include <optional>
#include <string>
#include <vector>

#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "simulation/twin.h"
#include "tables/export_rule.h"
#include "tables/tables.h"

namespace fluxcal::tables {

inline MachineLimits TwinLimits(double i_max_a = 150.0) {
  MachineLimits lim;
  lim.pole_pairs = sim::MotorParams().pole_pairs;
  lim.rs_ohm = sim::MotorParams().rs_ohm;
  lim.udc_v = sim::DriveParams().udc_v;
  lim.i_max_a = i_max_a;
  return lim;
}

// The twin motor with cross saturation (g_cross 3e-5 H): past its MTPV
// onset within the tests' speeds. One instance for every test.
inline const sim::AnalyticMotor& SaturatedTwin() {
  static const sim::AnalyticMotor m{[] {
    sim::MotorParams p;
    p.sat.g_cross_h = 3e-5;
    return p;
  }()};
  return m;
}

// A small table as the export tests read it back: 5 rows, 4 speeds up to
// `speed_max_rpm`, labelled with a serial, version and model.
inline TableSpec SmallLabelledSpec(const std::string& kind, double speed_max_rpm) {
  TableSpec spec;
  spec.kind = kind;
  spec.points = 5;
  spec.speed_points = 4;
  spec.speed_max_rpm = speed_max_rpm;
  spec.serial = "IPM-T-1";
  spec.calibration_version = 3;
  spec.model = "analytic";
  return spec;
}

// A table of `kind` with `points` rows and `speed_points` speeds.
inline TableSpec GridSpec(const std::string& kind, int points, int speed_points) {
  TableSpec spec;
  spec.kind = kind;
  spec.points = points;
  spec.speed_points = speed_points;
  return spec;
}

// An export request that takes clamped cells (the twin's tables over a Udc
// axis clamp at the low voltages).
inline ExportRequest ClampedAllowed() {
  ExportRequest r;
  r.allow_clamped = true;
  return r;
}

// The twin motor fitted from its own flux linkage on a grid (id -150..0 A,
// iq 0..150 A: measured current limit 150 A), with the facts given.
inline fit::Calibration TwinCalibration(std::optional<double> udc_v, std::optional<double> rs_ohm) {
  const sim::AnalyticMotor motor{sim::MotorParams{}};
  fit::FitData d;
  d.serial = "IPM-RULE-1";
  d.pole_pairs = sim::MotorParams().pole_pairs;
  d.rs_ohm = rs_ohm;
  d.udc_v = udc_v;
  for (int a = 0; a <= 10; ++a) {
    for (int b = 0; b <= 10; ++b) {
      const double id = -150.0 + 15 * a, iq = 15.0 * b;
      const auto f = motor.Flux(id, iq);
      d.fluxes.push_back({id, iq, f.psi_d_wb, f.psi_q_wb, 1e-6});
    }
  }
  d.psi_pm_prior_wb = motor.Flux(0, 0).psi_d_wb;
  fit::FitOptions o;
  o.model = "analytic";
  auto cal = fit::Fit(d, o);
  EXPECT_TRUE(cal.ok()) << cal.status();
  return *cal;
}

// The values of a table's output `name` (a test failure when it has none).
inline const std::vector<double>& Out(const Table& t, const std::string& name) {
  for (const auto& o : t.outputs) {
    if (o.name == name) return o.values;
  }
  ADD_FAILURE() << "no output " << name;
  static const std::vector<double> none;
  return none;
}

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TESTS_TABLES_TWIN_LIMITS_H_
