// The torque-speed envelope, tables over a Udc axis and the magnet
// temperature (docs/tables.md, "The envelope", "Tables over Udc",
// "Magnet temperature"): against the closed form of a linear machine, and
// the properties every machine's envelope has.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <numbers>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_format.h"
#include "gtest/gtest.h"
#include "physics/speed.h"
#include "simulation/twin.h"
#include "tables/export_rule.h"
#include "tables/tables.h"
#include "tests/tables/c_unit.h"
#include "tests/tables/twin_limits.h"
#include "tinyxml2.h"

namespace fluxcal::tables {
namespace {

constexpr double kPi = std::numbers::pi;

// A surface-magnet machine with constant inductance:
//   psi_d = psi_pm + L id,  psi_q = L iq,  T = 1.5 p psi_pm iq.
// Its limits have closed forms with Rs = 0 (Morimoto, Takeda, Hirasa,
// Taniguchi, "Expansion of operating limits for permanent magnet motor by
// current vector control considering inverter capacity", IEEE Trans. Ind.
// Appl. 26(5), 1990; the same in Bianchi and Bolognani, "Parameters and
// volt-ampere ratings of a synchronous motor drive for flux-weakening
// applications", IEEE Trans. Power Electron. 12(5), 1997), with
// u = u_max / w_e the flux the voltage limit allows:
//   below base speed (MTPA, id = 0): T = 1.5 p psi_pm I;
//   base speed w_b = u_max / sqrt(psi_pm^2 + (L I)^2);
//   above it, on both circles: id = (u^2 - psi_pm^2 - L^2 I^2) / (2 psi_pm L),
//     iq = sqrt(I^2 - id^2), T = 1.5 p psi_pm iq;
//   characteristic current i_ch = psi_pm / L:
//     i_ch > I: no torque beyond w_max = u_max / (psi_pm - L I);
//     i_ch < I: from w_v = u_max / (L sqrt(I^2 - i_ch^2)) on, MTPV at
//       id = -i_ch, iq = u / L: T = 1.5 p psi_pm u / L, constant power
//       P = T w_e / p = 1.5 psi_pm u_max / L.
class LinearSpm : public sim::MagneticModel {
 public:
  LinearSpm(double psi_pm_wb, double l_h) : psi_(psi_pm_wb), l_(l_h) {}
  sim::FluxLinkage Flux(double id, double iq, double) const override { return {psi_ + l_ * id, l_ * iq}; }
  sim::DifferentialInductance Inductance(double, double, double) const override { return {l_, l_, 0.0}; }

 private:
  double psi_, l_;
};

struct Expected {
  double torque_nm, id_a, iq_a;
};
// The closed form above at electrical speed we.
Expected ClosedForm(double psi, double l, int p, double i_max, double u_max, double we) {
  const double u = we > 0 ? u_max / we : 1e300;
  const double ich = psi / l;
  const double wb = u_max / std::hypot(psi, l * i_max);
  if (we <= wb) return {1.5 * p * psi * i_max, 0.0, i_max};
  if (ich < i_max) {
    const double wv = u_max / (l * std::sqrt(i_max * i_max - ich * ich));
    if (we >= wv) return {1.5 * p * psi * u / l, -ich, u / l};
  } else if (we >= u_max / (psi - l * i_max)) {
    return {0.0, 0.0, 0.0};
  }
  const double id = (u * u - psi * psi - l * l * i_max * i_max) / (2 * psi * l);
  const double iq = std::sqrt(i_max * i_max - id * id);
  return {1.5 * p * psi * iq, id, iq};
}

MachineLimits LinearLimits(double udc_v) {
  MachineLimits lim;
  lim.pole_pairs = 4;
  lim.rs_ohm = 0.0;
  lim.udc_v = udc_v;
  lim.i_max_a = 150;
  return lim;
}

TableSpec EnvelopeSpec(double speed_max_rpm, int points = 41) {
  TableSpec s;
  s.kind = "envelope";
  s.speed_max_rpm = speed_max_rpm;
  s.speed_points = points;
  return s;
}

TEST(Envelope, LinearMachineMatchesTheClosedForm) {
  // psi_pm 0.05 Wb; L 0.2 mH (i_ch 250 A > I: a top speed) and 0.5 mH
  // (i_ch 100 A < I: MTPV and constant power to any speed); 48 V.
  for (const double l : {0.2e-3, 0.5e-3}) {
    SCOPED_TRACE(absl::StrFormat("L = %g mH", l * 1e3));
    const LinearSpm m(0.05, l);
    const MachineLimits lim = LinearLimits(48);
    auto t = BuildTable(m, lim, EnvelopeSpec(8000, 81));
    ASSERT_TRUE(t.ok()) << t.status();
    ASSERT_EQ(t->axes.size(), 1u);
    const auto& n = t->axes[0].values;
    const double t0 = 1.5 * 4 * 0.05 * 150;   // 45 N m
    size_t fw = 0, none = 0;
    double worst_nm = 0, worst_a = 0;
    for (size_t k = 0; k < n.size(); ++k) {
      const double we = physics::RpmToElectricalRadS(n[k], 4);
      const Expected e = ClosedForm(0.05, l, 4, 150, lim.UMaxV(), we);
      const double tq = Out(*t, "torque_nm")[k];
      worst_nm = std::max(worst_nm, std::abs(tq - e.torque_nm));
      if (e.torque_nm > 0.02 * t0) {
        worst_a = std::max({worst_a, std::abs(Out(*t, "id_a")[k] - e.id_a), std::abs(Out(*t, "iq_a")[k] - e.iq_a)});
      }
      // Tolerance: 0.01 % of the standstill torque (the limit torque is
      // solved to 1e-9 of its value; observed 1e-7 %).
      EXPECT_NEAR(tq, e.torque_nm, 1e-4 * t0) << n[k] << " rpm: expected " << e.torque_nm << " N m, got " << tq;
      EXPECT_NEAR(Out(*t, "power_w")[k], tq * n[k] * 2 * kPi / 60, 1e-9 * t0 * 1e3) << n[k] << " rpm";
      if (e.torque_nm > 0.02 * t0) {
        // The operating point: 0.05 A (the torque near a flat optimum pins
        // the current less tightly than the torque; observed 5 mA).
        EXPECT_NEAR(Out(*t, "id_a")[k], e.id_a, 0.05) << n[k] << " rpm: id";
        EXPECT_NEAR(Out(*t, "iq_a")[k], e.iq_a, 0.05) << n[k] << " rpm: iq";
        EXPECT_EQ(t->clamped[k], 0) << n[k] << " rpm";
      }
      if (e.torque_nm == 0) {
        ++none;
        EXPECT_EQ(t->clamped[k], 1) << n[k] << " rpm is beyond the top speed: no torque, flagged";
        EXPECT_EQ(tq, 0.0);
      }
      fw += e.id_a < -1;
    }
    EXPECT_GT(fw, 10u) << "the speed range reaches field weakening";
    std::printf("L %.1f mH: %zu speeds, %zu in field weakening, %zu without torque; largest error %.3g N m "
                "(%.2g %% of %.0f N m), current %.3g A\n",
                l * 1e3, n.size(), fw, none, worst_nm, 100 * worst_nm / t0, t0, worst_a);
    if (l < 0.3e-3) {
      // Top speed u_max / (psi - L I) = 27.71 V / 0.02 Wb = 1386 rad/s, 3308 rpm.
      EXPECT_GT(none, 10u);
    } else {
      // MTPV: constant power 1.5 psi u_max / L = 1.5 * 0.05 * 27.71 / 0.5e-3 = 4157 W.
      const double p_mtpv = 1.5 * 0.05 * lim.UMaxV() / l;
      EXPECT_NEAR(Out(*t, "power_w").back(), p_mtpv, 1e-3 * p_mtpv);
      EXPECT_EQ(none, 0u);
    }
  }
}

// Torque never rises with speed, and a higher Udc never gives less torque
// at any speed: on the saturated twin (cross saturation) and its fit.
TEST(Envelope, TorqueFallsWithSpeedAndRisesWithUdc) {
  const sim::AnalyticMotor& motor = SaturatedTwin();
  const fit::Calibration cal = TwinCalibration(50.0, sim::MotorParams().rs_ohm);
  for (const sim::MagneticModel* m : {static_cast<const sim::MagneticModel*>(&motor),
                                      static_cast<const sim::MagneticModel*>(&cal)}) {
    SCOPED_TRACE(m == &motor ? "twin motor" : "fitted calibration");
    std::vector<double> prev;
    for (const double udc : {30.0, 40.0, 50.0, 60.0, 80.0}) {
      MachineLimits lim = TwinLimits();
      lim.udc_v = udc;
      auto t = BuildTable(*m, lim, EnvelopeSpec(8000, 41));
      ASSERT_TRUE(t.ok()) << t.status();
      const auto& n = t->axes[0].values;
      const auto& tq = Out(*t, "torque_nm");
      for (size_t k = 1; k < n.size(); ++k) {
        // 1e-6 relative: the limit torque is found to 1e-9 of its value.
        EXPECT_LE(tq[k], tq[k - 1] * (1 + 1e-6) + 1e-9)
            << "Udc " << udc << " V: " << n[k] << " rpm gives more torque than " << n[k - 1] << " rpm";
      }
      if (!prev.empty()) {
        for (size_t k = 0; k < n.size(); ++k) {
          EXPECT_GE(tq[k], prev[k] * (1 - 1e-6) - 1e-9)
              << n[k] << " rpm: Udc " << udc << " V gives " << tq[k] << " N m, the lower Udc " << prev[k] << " N m";
        }
      }
      prev = tq;
    }
  }
}

TEST(Envelope, NeedsTheVoltageLimit) {
  const LinearSpm m(0.05, 0.2e-3);
  MachineLimits lim = LinearLimits(48);
  lim.udc_v.reset();
  auto t = BuildTable(m, lim, EnvelopeSpec(4000));
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.status().message().find("udc_v (--udc-v)"), std::string::npos) << t.status();
}

TEST(UdcAxis, ParsesListsAndRangesAndRefusesTheRest) {
  auto a = ParseUdcAxis("250,300,350,400");
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(*a, (std::vector<double>{250, 300, 350, 400}));
  auto r = ParseUdcAxis("200:400:5");
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(*r, (std::vector<double>{200, 250, 300, 350, 400}));
  for (const char* bad : {"300,250", "0,100", "100,x", "100:50:3", "100:200:1", "1:2:3:4", "100,100.0000001"}) {
    auto b = ParseUdcAxis(bad);
    EXPECT_FALSE(b.ok()) << bad;
    EXPECT_EQ(b.status().message().rfind("flag --udc-axis-v", 0), 0u) << b.status();
  }
  EXPECT_EQ(UdcTag(300), "udc300v");
  EXPECT_EQ(UdcTag(312.5), "udc312p5v");
}

// Every table of a Udc axis holds the values of the single export at its
// voltage, bit for bit (axes, outputs, flags, payload checksums), under
// its own labels.
TEST(UdcAxis, TablesEqualTheSingleUdcExportsBitForBit) {
  const fit::Calibration cal = TwinCalibration(50.0, sim::MotorParams().rs_ohm);
  const std::vector<double> udcs = {40, 50, 60};
  for (const char* kind : {"fw", "mtpv", "mtpa", "envelope"}) {
    SCOPED_TRACE(kind);
    const TableSpec spec = GridSpec(kind, 16, 12);
    const ExportRequest req = ClampedAllowed();
    auto axis = BuildExportTablesOverUdc(cal, spec, req, udcs);
    ASSERT_TRUE(axis.ok()) << axis.status();
    ASSERT_EQ(axis->size(), udcs.size());
    for (size_t k = 0; k < udcs.size(); ++k) {
      ExportRequest one = req;
      one.udc_v = udcs[k];
      auto single = BuildExportTable(cal, spec, one);
      ASSERT_TRUE(single.ok()) << single.status();
      const Table &a = (*axis)[k].table, &s = single->table;
      ASSERT_EQ(a.axes.size(), s.axes.size());
      for (size_t i = 0; i < a.axes.size(); ++i) EXPECT_EQ(a.axes[i].values, s.axes[i].values);
      ASSERT_EQ(a.outputs.size(), s.outputs.size());
      for (size_t i = 0; i < a.outputs.size(); ++i) {
        EXPECT_EQ(a.outputs[i].name, s.outputs[i].name);
        EXPECT_EQ(a.outputs[i].values, s.outputs[i].values) << a.outputs[i].name << " at " << udcs[k] << " V";
      }
      EXPECT_EQ(a.clamped, s.clamped);
      EXPECT_EQ(a.extrapolated, s.extrapolated);
      EXPECT_EQ(a.by_symmetry, s.by_symmetry);
      EXPECT_EQ(a.not_positive_definite, s.not_positive_definite);
      EXPECT_EQ(a.sha256, s.sha256);
      EXPECT_EQ(a.crc32, s.crc32);
      EXPECT_EQ(a.limits.udc_v, std::optional<double>(udcs[k]));
      // Labels carry the voltage; the single export's do not.
      const std::string tag = absl::StrFormat("UDC%gV", udcs[k]);
      EXPECT_EQ(Label(a, "id_a"), absl::StrFormat("FLUXCAL_%s_%s_ID_A", absl::AsciiStrToUpper(kind), tag));
      EXPECT_EQ(Label(s, "id_a"), absl::StrFormat("FLUXCAL_%s_ID_A", absl::AsciiStrToUpper(kind)));
      for (Format f : {Format::kCsv, Format::kJson, Format::kCHeader, Format::kCdfx, Format::kDcm, Format::kA2l}) {
        auto ea = Export(a, f), es = Export(s, f);
        ASSERT_TRUE(ea.ok() && es.ok());
        EXPECT_EQ(ea->payload_sha256, es->payload_sha256);
        if (f != Format::kCsv && f != Format::kJson) {
          EXPECT_NE(ea->bytes.find(Label(a, "id_a")), std::string::npos) << "format " << static_cast<int>(f);
        }
      }
    }
  }
  // An axis built by hand is held to ParseUdcAxis' rules: no two tables
  // under one label.
  for (const std::vector<double>& bad : std::vector<std::vector<double>>{{50, 40}, {50, 50.0000001}, {0, 50}}) {
    auto r = BuildExportTablesOverUdc(cal, TableSpec{}, ClampedAllowed(), bad);
    EXPECT_FALSE(r.ok()) << bad[0] << ", " << bad[1];
  }
  ExportRequest both;
  both.udc_v = 50;
  auto refused = BuildExportTablesOverUdc(cal, TableSpec{}, both, udcs);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().message().rfind("flag --udc-v", 0), 0u) << refused.status();
}

// The point of the tags: the C headers of every Udc of an axis compile into
// one C99 unit together, each array holding its own table.
TEST(UdcAxis, HeadersOfEveryUdcCompileIntoOneUnit) {
  if (std::system("cc --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "no C compiler (cc)";
  const fit::Calibration cal = TwinCalibration(50.0, sim::MotorParams().rs_ohm);
  TableSpec spec;
  spec.kind = "fw";
  spec.points = 9;
  spec.speed_points = 7;
  ExportRequest req;
  req.allow_clamped = true;
  const std::vector<double> udcs = {40, 62.5};
  auto axis = BuildExportTablesOverUdc(cal, spec, req, udcs);
  ASSERT_TRUE(axis.ok()) << axis.status();
  std::vector<std::pair<std::string, std::string>> headers;
  std::string prog = "#include <stdio.h>\n";
  for (const auto& b : *axis) {
    auto h = Export(b.table, Format::kCHeader);
    ASSERT_TRUE(h.ok()) << h.status();
    headers.push_back({b.table.label_tag + ".h", h->bytes});
    prog += "#include \"" + b.table.label_tag + ".h\"\n";
  }
  prog += "int main(void) {\n  unsigned k;\n";
  for (const auto& b : *axis) {
    const std::string id = CSymbol(b.table, "id_a");
    prog += "  for (k = 0; k < " + Label(b.table, "id_a") + "_LEN; ++k) printf(\"%.17g\\n\", " + id + "[k]);\n";
  }
  prog += "  return 0;\n}\n";
  std::string printed;
  ASSERT_NO_FATAL_FAILURE(BuildAndRunC99("fluxcal_udc_axis_h", headers, prog, "",
                                         "compiling both headers into one unit failed", &printed));
  const std::vector<double> got = PrintedNumbers(printed);
  std::vector<double> want;
  for (const auto& b : *axis) {
    want.insert(want.end(), b.table.outputs[0].values.begin(), b.table.outputs[0].values.end());
  }
  EXPECT_EQ(got, want);
  EXPECT_NE((*axis)[0].table.outputs[0].values, (*axis)[1].table.outputs[0].values);
}

// The generating envelope (TableSpec::envelope_generating, `fluxcal export
// --table envelope --generating`): the limit with torque and power <= 0, at
// standstill the motoring limit's magnitude on a model symmetric in iq
// (there is no voltage drop to tell the directions apart), at speed at least
// the motoring one (the resistive drop helps when generating), its operating
// points the motoring ones mirrored in iq at standstill; labels of its own,
// so that both headers compile into one unit; any other table refuses the
// flag, naming it.
TEST(Envelope, GeneratingIsTheNegativeLimitUnderLabelsOfItsOwn) {
  const fit::Calibration cal = TwinCalibration(50.0, sim::MotorParams().rs_ohm);
  TableSpec spec = EnvelopeSpec(8000, 17);
  ExportRequest req;
  req.allow_clamped = true;
  auto mot = BuildExportTable(cal, spec, req);
  spec.envelope_generating = true;
  auto gen = BuildExportTable(cal, spec, req);
  ASSERT_TRUE(mot.ok() && gen.ok()) << mot.status() << gen.status();
  const Table &m = mot->table, &g = gen->table;
  EXPECT_FALSE(m.envelope_generating);
  EXPECT_TRUE(g.envelope_generating);
  ASSERT_EQ(m.axes[0].values, g.axes[0].values);
  const auto &tm = Out(m, "torque_nm"), &tg = Out(g, "torque_nm"), &pg = Out(g, "power_w");
  const auto &iqm = Out(m, "iq_a"), &iqg = Out(g, "iq_a"), &idm = Out(m, "id_a"), &idg = Out(g, "id_a");
  size_t torque = 0;
  for (size_t k = 0; k < tg.size(); ++k) {
    EXPECT_LE(tg[k], 0.0) << k;
    EXPECT_LE(pg[k], 0.0) << k;
    EXPECT_FALSE(std::signbit(pg[k]) && pg[k] == 0) << "power -0 at " << g.axes[0].values[k] << " rpm";
    if (!g.clamped[k]) {
      ++torque;
      EXPECT_LT(iqg[k], 0.0) << k;
      // 1e-6 relative: each limit is solved to 1e-9 of its value.
      EXPECT_GE(-tg[k], tm[k] * (1 - 1e-6)) << g.axes[0].values[k] << " rpm: generating below motoring";
    }
  }
  EXPECT_GT(torque, tg.size() / 2);
  // Standstill: the mirror image of the motoring limit.
  EXPECT_NEAR(-tg[0], tm[0], 1e-9 * tm[0]);
  EXPECT_NEAR(idg[0], idm[0], 1e-6);
  EXPECT_NEAR(iqg[0], -iqm[0], 1e-6);
  // A motoring-only bench: the generating points rest on the mirror image.
  EXPECT_TRUE(std::any_of(g.by_symmetry.begin(), g.by_symmetry.end(), [](uint8_t b) { return b; }));
  EXPECT_EQ(Label(m, "torque_nm"), "FLUXCAL_ENVELOPE_TORQUE_NM");
  EXPECT_EQ(Label(g, "torque_nm"), "FLUXCAL_ENVELOPE_GENERATING_TORQUE_NM");
  for (Format f : {Format::kCsv, Format::kJson, Format::kCHeader, Format::kCdfx, Format::kDcm, Format::kA2l}) {
    auto e = Export(g, f);
    ASSERT_TRUE(e.ok()) << e.status();
    EXPECT_NE(e->bytes.find(f == Format::kJson ? "\"generating\"" : "envelope (generating)"), std::string::npos)
        << "format " << static_cast<int>(f);
  }
  // The sign is stated in the file: torque_sign -1 (motoring +1).
  auto dm = Export(m, Format::kDcm), dg = Export(g, Format::kDcm);
  ASSERT_TRUE(dm.ok() && dg.ok());
  EXPECT_NE(dm->bytes.find("FESTWERT FLUXCAL_ENVELOPE_TORQUE_SIGN\n"), std::string::npos);
  EXPECT_NE(dg->bytes.find("FESTWERT FLUXCAL_ENVELOPE_GENERATING_TORQUE_SIGN\n"), std::string::npos);
  EXPECT_EQ(dg->bytes.find("FLUXCAL_ENVELOPE_TORQUE"), std::string::npos) << "a motoring label in the generating file";
  // Over a Udc axis: both tags.
  spec.speed_max_rpm = 6000;
  auto axis = BuildExportTablesOverUdc(cal, spec, req, {40, 62.5});
  ASSERT_TRUE(axis.ok()) << axis.status();
  EXPECT_EQ(Label((*axis)[1].table, "torque_nm"), "FLUXCAL_ENVELOPE_GENERATING_UDC62P5V_TORQUE_NM");
  ExportRequest one = req;
  one.udc_v = 62.5;
  auto single = BuildExportTable(cal, spec, one);
  ASSERT_TRUE(single.ok()) << single.status();
  EXPECT_EQ(Out((*axis)[1].table, "torque_nm"), Out(single->table, "torque_nm"));
  // Only the envelope takes the flag.
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    TableSpec bad = spec;
    bad.kind = kind;
    auto r = BuildExportTable(cal, bad, req);
    ASSERT_FALSE(r.ok()) << kind;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(r.status().message().rfind("flag --generating: only with --table envelope", 0), 0u) << r.status();
    ExportRequest rpc = req;
    rpc.names_flags = false;
    EXPECT_EQ(CheckExportSpec(bad, rpc).message().rfind("generating: only with table envelope", 0), 0u);
  }
  // Side by side in one ECU build: both headers in one C unit.
  if (std::system("cc --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "no C compiler (cc)";
  std::vector<std::pair<std::string, std::string>> headers;
  std::string prog = "#include <stdio.h>\n#include \"m.h\"\n#include \"g.h\"\nint main(void) {\n";
  for (const auto& [t, name] : {std::pair<const Table*, const char*>{&m, "m"}, {&g, "g"}}) {
    auto h = Export(*t, Format::kCHeader, ExportOptions{});
    ASSERT_TRUE(h.ok()) << h.status();
    headers.push_back({std::string(name) + ".h", h->bytes});
    prog += "  printf(\"%.17g\\n\", " + CSymbol(*t, "torque_nm") + "[0]);\n";
  }
  prog += "  return 0;\n}\n";
  std::string printed;
  ASSERT_NO_FATAL_FAILURE(BuildAndRunC99("fluxcal_generating_h", headers, prog, "",
                                         "the motoring and generating headers do not compile together", &printed));
  EXPECT_EQ(PrintedNumbers(printed), (std::vector<double>{tm[0], tg[0]}));
}

TEST(MagnetTemperature, RefusedWithoutTheCalibrationsCoefficient) {
  const fit::Calibration cal = TwinCalibration(50.0, sim::MotorParams().rs_ohm);
  TableSpec spec;
  spec.kind = "envelope";
  ExportRequest req;
  req.magnet_temp_c = 120;
  auto t = BuildExportTable(cal, spec, req);
  ASSERT_FALSE(t.ok());
  EXPECT_EQ(t.status().code(), absl::StatusCode::kInvalidArgument);
  const std::string msg(t.status().message());
  EXPECT_EQ(msg.rfind("flag --magnet-temp-c", 0), 0u) << msg;
  EXPECT_NE(msg.find("states no magnet temperature coefficient"), std::string::npos) << msg;
  req.names_flags = false;
  auto rpc = BuildExportTable(cal, spec, req);
  ASSERT_FALSE(rpc.ok());
  EXPECT_EQ(std::string(rpc.status().message()).rfind("magnet_temp_c", 0), 0u) << rpc.status();
}

// With a coefficient stated, psi_pm scales and the linear machine's closed
// form moves with it: standstill torque 1.5 p psi I, base speed
// u_max / sqrt(psi^2 + (L I)^2).
TEST(MagnetTemperature, ScalesPsiPmByTheStatedCoefficient) {
  const LinearSpm m(0.05, 0.2e-3);
  const MachineLimits lim = LinearLimits(48);
  TableSpec spec = EnvelopeSpec(8000, 81);
  spec.magnet_temperature = MagnetTemperature{-0.001, 20, 120};   // NdFeB-like, +100 K: psi x 0.9
  auto t = BuildTable(m, lim, spec);
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_NEAR(t->psi_pm_wb, 0.045, 1e-12);
  const auto& n = t->axes[0].values;
  for (size_t k = 0; k < n.size(); ++k) {
    const Expected e = ClosedForm(0.045, 0.2e-3, 4, 150, lim.UMaxV(), physics::RpmToElectricalRadS(n[k], 4));
    EXPECT_NEAR(Out(*t, "torque_nm")[k], e.torque_nm, 1e-3 * 45) << n[k] << " rpm";
  }
  bool states = false;
  for (const auto& s : Scalars(*t)) states |= s.name == "magnet_temperature_c" && s.value == 120;
  EXPECT_TRUE(states);
  // Every format writes the magnet scalars.
  for (Format f : {Format::kCsv, Format::kJson, Format::kCHeader, Format::kCdfx, Format::kDcm, Format::kA2l}) {
    auto e = Export(*t, f);
    ASSERT_TRUE(e.ok()) << e.status();
    EXPECT_NE(absl::AsciiStrToLower(e->bytes).find("magnet_alpha_per_k"), std::string::npos) << static_cast<int>(f);
  }
}

// The figure: one curve per Udc in each panel, extrapolated stretches
// dotted (the report page's key) and named in the legend.
TEST(Envelope, FigureHasOneCurvePerUdcAndDotsTheExtrapolated) {
  const fit::Calibration cal = TwinCalibration(50.0, sim::MotorParams().rs_ohm);
  TableSpec spec;
  spec.kind = "envelope";
  spec.speed_points = 16;
  spec.allow_extrapolation = true;
  ExportRequest req;
  req.i_max_a = 180;   // beyond the measured 150 A: the low speeds extrapolated
  req.allow_clamped = true;
  auto axis = BuildExportTablesOverUdc(cal, spec, req, {40, 60});
  ASSERT_TRUE(axis.ok()) << axis.status();
  std::vector<Table> envs;
  size_t ext = 0;
  for (const auto& b : *axis) {
    envs.push_back(b.table);
    for (auto e : b.table.extrapolated) ext += e;
  }
  ASSERT_GT(ext, 0u);
  const std::string svg = PlotEnvelopeSvg(envs);
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
  EXPECT_NE(svg.find("Udc 40 V"), std::string::npos);
  EXPECT_NE(svg.find("Udc 60 V"), std::string::npos);
  EXPECT_NE(svg.find("dotted: extrapolated"), std::string::npos);
  size_t dotted = 0, solid = 0;
  std::function<void(const tinyxml2::XMLElement*)> walk = [&](const tinyxml2::XMLElement* e) {
    for (; e != nullptr; e = e->NextSiblingElement()) {
      const char* cls = e->Attribute("class");
      const char* d = e->Attribute("d");
      if (cls != nullptr && std::string(cls) == "line" && d != nullptr && *d != '\0') {
        const char* dash = e->Attribute("stroke-dasharray");
        (dash != nullptr && std::string(dash) == "2 3" ? dotted : solid) += 1;
      }
      walk(e->FirstChildElement());
    }
  };
  walk(doc.RootElement());
  EXPECT_GE(dotted, 4u) << "an extrapolated stretch per Udc and panel";
  EXPECT_GE(solid, 4u) << "a measured stretch per Udc and panel";
}

}  // namespace
}  // namespace fluxcal::tables
