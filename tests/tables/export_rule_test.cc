// The export rule (tables/export_rule.h), the one place that decides what a
// table is computed for: Udc and Rs from the request or the calibration,
// never assumed; the current limit from the request or the measured one,
// never a fallback; a mostly clamped table refused unless asked for. And
// the round breakpoints every table now has (tables.h, TableSpec).
#include "tables/export_rule.h"

#include <cmath>

#include "gtest/gtest.h"
#include "fitting/fit.h"
#include "simulation/twin.h"
#include "tables/tables.h"
#include "tests/tables/twin_limits.h"

namespace fluxcal::tables {
namespace {

bool Has(const absl::Status& s, const std::string& what) {
  return std::string(s.message()).find(what) != std::string::npos;
}

const fit::Calibration& WithUdc() {
  static const auto* c = new fit::Calibration(TwinCalibration(sim::DriveParams().udc_v, sim::MotorParams().rs_ohm));
  return *c;
}
const fit::Calibration& WithoutUdc() {
  static const auto* c = new fit::Calibration(TwinCalibration(std::nullopt, sim::MotorParams().rs_ohm));
  return *c;
}

TEST(ExportRule, UdcFromTheRequestOrTheCalibrationNeverAssumed) {
  const auto& bare = WithoutUdc();
  ASSERT_FALSE(bare.udc_v().has_value());
  for (const char* kind : {"fw", "mtpv"}) {
    ExportRequest cli;
    auto r = ResolveExportLimits(bare, kind, cli);
    ASSERT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << kind;
    EXPECT_TRUE(Has(r.status(), "flag --udc-v")) << r.status();
    ExportRequest rpc;
    rpc.names_flags = false;
    r = ResolveExportLimits(bare, kind, rpc);
    ASSERT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << kind;
    EXPECT_EQ(r.status().message().rfind("udc_v: ", 0), 0u) << r.status();
    EXPECT_FALSE(Has(r.status(), "--")) << "the service names fields, not flags: " << r.status();
  }
  // MTPA needs none, and none is invented.
  auto mtpa = ResolveExportLimits(bare, "mtpa", {});
  ASSERT_TRUE(mtpa.ok()) << mtpa.status();
  EXPECT_FALSE(mtpa->limits.udc_v.has_value());
  EXPECT_TRUE(mtpa->udc_source.empty());
  // The calibration's, said so; a request's replaces it, said so.
  auto fw = ResolveExportLimits(WithUdc(), "fw", {});
  ASSERT_TRUE(fw.ok()) << fw.status();
  EXPECT_EQ(*fw->limits.udc_v, sim::DriveParams().udc_v);
  EXPECT_EQ(fw->udc_source, "the calibration");
  EXPECT_TRUE(fw->overridden.empty());
  ExportRequest given;
  given.udc_v = 48;
  fw = ResolveExportLimits(WithUdc(), "fw", given);
  ASSERT_TRUE(fw.ok());
  EXPECT_EQ(*fw->limits.udc_v, 48.0);
  EXPECT_EQ(fw->udc_source, "--udc-v");
  EXPECT_TRUE(fw->overridden.find("replaces the calibration's 50 V") != std::string::npos) << fw->overridden;
  given.udc_v = -1;
  EXPECT_EQ(ResolveExportLimits(WithUdc(), "fw", given).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(ExportRule, FieldWeakeningNeedsRs) {
  const fit::Calibration no_rs = TwinCalibration(sim::DriveParams().udc_v, std::nullopt);
  ASSERT_FALSE(no_rs.rs_ohm().has_value());
  auto fw = ResolveExportLimits(no_rs, "fw", {});
  ASSERT_EQ(fw.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Has(fw.status(), "flag --rs-ohm")) << fw.status();
  EXPECT_TRUE(ResolveExportLimits(no_rs, "mtpv", {}).ok()) << "the MTPV points do not depend on Rs";
  ExportRequest given;
  given.rs_ohm = 0.011;
  EXPECT_TRUE(ResolveExportLimits(no_rs, "fw", given).ok());
  // BuildTable itself refuses a field-weakening map without a voltage limit.
  MachineLimits lim = TwinLimits();
  lim.rs_ohm.reset();
  TableSpec spec;
  spec.kind = "fw";
  EXPECT_EQ(BuildTable(no_rs, lim, spec).status().code(), absl::StatusCode::kInvalidArgument);
}

// One current-limit rule for the CLI and the service: the request's, else
// the measured one; a calibration without a measured current circle is
// refused (the service once fell back to 150 A there, the CLI did not).
TEST(ExportRule, CurrentLimitFromTheRequestOrTheMeasuredRegion) {
  auto r = ResolveExportLimits(WithUdc(), "mtpa", {});
  ASSERT_TRUE(r.ok());
  EXPECT_NEAR(r->limits.i_max_a, WithUdc().MeasuredCurrentLimitA(), 1e-9);
  EXPECT_GT(r->limits.i_max_a, 100.0);
  EXPECT_EQ(r->i_max_source, "the calibration's measured current limit");
  const auto& c = WithUdc();
  // The same surfaces measured at id >= 0 only: no current circle inside.
  const fit::Calibration no_circle(c.serial(), c.family(), c.params(), c.covariance(), c.pole_pairs(), c.rs_ohm(),
                                   0.0, 20.0, 0.0, 150.0);
  ASSERT_EQ(no_circle.MeasuredCurrentLimitA(), 0.0);
  for (bool flags : {true, false}) {
    ExportRequest req;
    req.names_flags = flags;
    auto refused = ResolveExportLimits(no_circle, "mtpa", req);
    ASSERT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_TRUE(Has(refused.status(), flags ? "flag --i-max-a" : "i_max_a: ")) << refused.status();
    req.i_max_a = 100;
    auto given = ResolveExportLimits(no_circle, "mtpa", req);
    ASSERT_TRUE(given.ok()) << given.status();
    EXPECT_EQ(given->limits.i_max_a, 100.0);
  }
}

TEST(ExportRule, MostlyClampedIsRefusedUnlessAskedFor) {
  TableSpec spec;
  spec.kind = "fw";
  spec.points = 9;
  spec.speed_points = 8;
  ExportRequest low;
  low.udc_v = 8;   // the twin at 8 V: the voltage limit binds from a few hundred rpm
  auto refused = BuildExportTable(WithUdc(), spec, low);
  ASSERT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition) << refused.status();
  for (const char* what : {"cells (", "clamped, more than 50 %", "the voltage limit u_max", "Udc 8 V", "--allow-clamped"}) {
    EXPECT_TRUE(Has(refused.status(), what)) << what << " in: " << refused.status();
  }
  low.allow_clamped = true;
  auto allowed = BuildExportTable(WithUdc(), spec, low);
  ASSERT_TRUE(allowed.ok()) << allowed.status();
  EXPECT_GT(allowed->clamped.share, kMaxClampedShare);
  EXPECT_EQ(allowed->clamped.cells, allowed->table.clamped.size());
  low.names_flags = false;
  low.allow_clamped = false;
  EXPECT_TRUE(Has(BuildExportTable(WithUdc(), spec, low).status(), "give allow_clamped"));
  // At the drive's own 50 V the map is mostly feasible: exported, the
  // clamped share reported.
  auto fine = BuildExportTable(WithUdc(), spec, {});
  ASSERT_TRUE(fine.ok()) << fine.status();
  EXPECT_LE(fine->clamped.share, kMaxClampedShare);
  EXPECT_GT(fine->clamped.clamped, 0u) << "this twin's map has a clamped corner at high speed";
  EXPECT_FALSE(fine->clamped.why.empty());
}

TEST(RoundBreakpoints, OneTwoFiveStepsWithZeroAtMostN) {
  auto v = RoundBreakpoints(-47.3, 47.3, 64);
  ASSERT_TRUE(v.ok());
  // (2 x 47.3) / 63 = 1.50: step 2 (1 would give 95 rows).
  EXPECT_EQ(v->size(), 47u);
  EXPECT_EQ(v->front(), -46.0);
  EXPECT_EQ(v->back(), 46.0);
  EXPECT_EQ((*v)[23], 0.0);
  EXPECT_FALSE(std::signbit((*v)[23])) << "0, not -0";
  v = RoundBreakpoints(0, 6000, 32);
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->size(), 31u);
  EXPECT_EQ(v->back(), 6000.0) << "a range end on the grid is a breakpoint";
  v = RoundBreakpoints(0.00631, 0.0139, 64);
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->front(), 0.0064);   // step 0.0002, the doubles nearest the decimals
  EXPECT_EQ((*v)[1], 0.0066);
  EXPECT_EQ(v->back(), 0.0138);
  EXPECT_LE(v->size(), 64u);
  v = RoundBreakpoints(0, 1, 2);
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(*v, (std::vector<double>{0.0, 1.0}));
  // Two rows cannot hold a symmetric torque axis with 0: refused, named.
  auto none = RoundBreakpoints(-1, 1, 2);
  EXPECT_EQ(none.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Has(none.status(), "--points")) << none.status();
  EXPECT_FALSE(RoundBreakpoints(1, 1, 8).ok());
}

// Every table's axes are round (tables.h, TableSpec): MTPA and FW torque
// rows within +-T_max with 0, the FW speeds within [0, speed_max], the
// MTPV fluxes; MTPA rows ask for no more than the machine gives.
TEST(RoundBreakpoints, EveryTableAxis) {
  const sim::AnalyticMotor m{sim::MotorParams{}};
  const MachineLimits lim = TwinLimits();
  const double tmax = MaxTorqueNm(m, lim, 0.0);
  auto round_step = [](const std::vector<double>& v) {
    const double step = v[1] - v[0];
    const double mant = step / std::pow(10.0, std::floor(std::log10(step) + 1e-9));
    return std::abs(mant - 1) < 1e-9 || std::abs(mant - 2) < 1e-9 || std::abs(mant - 5) < 1e-9;
  };
  TableSpec spec;
  spec.points = 40;
  auto mtpa = BuildTable(m, lim, spec);
  ASSERT_TRUE(mtpa.ok()) << mtpa.status();
  const auto& tq = mtpa->axes[0].values;
  EXPECT_LE(tq.size(), 40u);
  EXPECT_TRUE(round_step(tq)) << tq[1] - tq[0];
  EXPECT_NE(std::find(tq.begin(), tq.end(), 0.0), tq.end());
  EXPECT_EQ(tq.front(), -tq.back()) << "generating rows mirror the motoring ones";
  EXPECT_LE(tq.back(), tmax);
  EXPECT_GT(tq.back() + (tq[1] - tq[0]), tmax) << "the axis ends at the last round torque within T_max";
  for (auto c : mtpa->clamped) EXPECT_EQ(c, 0);
  spec.kind = "fw";
  spec.points = 9;
  spec.speed_points = 8;
  spec.speed_max_rpm = 6500;
  auto fw = BuildTable(m, lim, spec);
  ASSERT_TRUE(fw.ok()) << fw.status();
  const auto& n = fw->axes[1].values;
  EXPECT_TRUE(round_step(n));
  EXPECT_EQ(n.front(), 0.0);
  EXPECT_LE(n.back(), 6500.0);
  EXPECT_EQ(fw->speed_max_rpm, n.back()) << "the file states the axis' top";
  EXPECT_TRUE(round_step(fw->axes[0].values));
  spec.kind = "mtpv";
  spec.points = 16;
  spec.allow_extrapolation = true;
  auto mtpv = BuildTable(m, lim, spec);
  ASSERT_TRUE(mtpv.ok()) << mtpv.status();
  EXPECT_TRUE(round_step(mtpv->axes[0].values));
  EXPECT_LE(mtpv->axes[0].values.size(), 16u);
}

// MachineLimits carries no machine's defaults: BuildTable refuses what was
// not given, and a table states only the limits it was computed for.
TEST(MachineLimits, NothingAssumed) {
  const sim::AnalyticMotor m{sim::MotorParams{}};
  TableSpec spec;
  auto none = BuildTable(m, MachineLimits{}, spec);
  ASSERT_EQ(none.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Has(none.status(), "pole_pairs unknown")) << none.status();
  MachineLimits lim = TwinLimits();
  lim.i_max_a = 0;
  EXPECT_TRUE(Has(BuildTable(m, lim, spec).status(), "--i-max-a"));
  lim = TwinLimits();
  lim.udc_v.reset();
  spec.kind = "fw";
  auto fw = BuildTable(m, lim, spec);
  ASSERT_EQ(fw.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(Has(fw.status(), "udc_v (--udc-v)")) << fw.status();
  spec.kind = "mtpa";
  auto mtpa = BuildTable(m, lim, spec);
  ASSERT_TRUE(mtpa.ok()) << mtpa.status();
  for (const auto& s : Scalars(*mtpa)) {
    EXPECT_NE(s.name, "udc_v");
    EXPECT_NE(s.name, "u_max_v");
  }
  EXPECT_TRUE(std::isnan(lim.UMaxV()));
}

}  // namespace
}  // namespace fluxcal::tables
