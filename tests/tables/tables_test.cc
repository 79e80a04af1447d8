// Tables against brute force and physics, and every exporter through a
// parser (tinyxml2 for CDFX, hand parsers for DCM, CSV and the C header).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>
#include <regex>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/str_format.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "simulation/twin.h"
#include "io/sha256.h"
#include "plot/plot.h"
#include "tables/signature.h"
#include "tables/tables.h"
#include "tests/tables/c_unit.h"
#include "tests/tables/twin_limits.h"
#include "tinyxml2.h"

namespace fluxcal::tables {
namespace {

constexpr double kPi = std::numbers::pi;

// The wrong model: psi = psi_pm + L_diff(i) i, the differential inductance at
// each operating point used as if it were apparent.
class DifferentialAsApparent : public sim::MagneticModel {
 public:
  explicit DifferentialAsApparent(const sim::MagneticModel& t) : t_(t) {}
  sim::FluxLinkage Flux(double id, double iq, double T) const override {
    const auto L = t_.Inductance(id, iq, T);
    return {t_.Flux(0, 0, T).psi_d_wb + L.ldd_h * id + L.ldq_h * iq, L.ldq_h * id + L.lqq_h * iq};
  }
  sim::DifferentialInductance Inductance(double id, double iq, double T) const override {
    return t_.Inductance(id, iq, T);
  }
 private:
  const sim::MagneticModel& t_;
};

TEST(Sha256, NistVectors) {
  EXPECT_EQ(io::Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(io::Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(io::Sha256Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
}

TEST(Mtpa, WithinPointOnePercentOfBruteForce) {
  const auto& m = SaturatedTwin();
  MachineLimits lim = TwinLimits();
  TableSpec spec;
  spec.points = 17;
  auto t = BuildTable(m, lim, spec);
  ASSERT_TRUE(t.ok()) << t.status();
  const auto& tq = t->axes[0].values;
  const double tmax = *std::max_element(tq.begin(), tq.end());
  for (size_t k = 0; k < tq.size(); ++k) {
    const double id = t->outputs[0].values[k], iq = t->outputs[1].values[k];
    EXPECT_NEAR(TorqueNm(m, 4, id, iq), tq[k], 1e-3 * tmax) << "row " << k;
    if (std::abs(tq[k]) < 0.05 * tmax) continue;
    // Brute force: the least |i| on a dense grid among points within 0.05 %
    // of the requested torque.
    double best = 1e9;
    for (double a = -150; a <= 0; a += 0.25) {
      for (double b = 0; b <= 150; b += 0.25) {
        const double q = tq[k] < 0 ? -b : b;
        if (std::abs(TorqueNm(m, 4, a, q) - tq[k]) < 5e-4 * std::abs(tq[k])) best = std::min(best, std::hypot(a, q));
      }
    }
    EXPECT_LE(std::hypot(id, iq), best * 1.001) << "row " << k << " torque " << tq[k];
  }
}

TEST(FieldWeakening, RespectsLimitsAndDeliversTorque) {
  const auto& m = SaturatedTwin();
  MachineLimits lim = TwinLimits();
  TableSpec spec;
  spec.kind = "fw";
  spec.points = 9;
  spec.speed_points = 7;
  spec.speed_max_rpm = 4000;
  auto t = BuildTable(m, lim, spec);
  ASSERT_TRUE(t.ok());
  const size_t n1 = t->axes[1].values.size();
  for (size_t i = 0; i < t->axes[0].values.size(); ++i) {
    for (size_t j = 0; j < n1; ++j) {
      const double id = t->outputs[0].values[i * n1 + j], iq = t->outputs[1].values[i * n1 + j];
      const double we = t->axes[1].values[j] * 4 * 2 * kPi / 60;
      EXPECT_LE(std::hypot(id, iq), lim.i_max_a * 1.0001);
      EXPECT_LE(VoltageV(m, lim, id, iq, we), lim.UMaxV() * 1.0001);
      if (!t->clamped[i * n1 + j]) {
        EXPECT_NEAR(TorqueNm(m, 4, id, iq), t->axes[0].values[i], 1e-3 * t->axes[0].values.back());
      }
    }
  }
}

// Field weakening against brute force on a dense grid of the current disc:
// an unclamped cell uses no more current than the least-current grid point
// that delivers its torque (within 0.05 %) inside both limits; a clamped cell
// delivers at least the largest torque of any grid point inside the limits.
// Both within 0.1 % (the tolerance).
TEST(FieldWeakening, WithinPointOnePercentOfBruteForce) {
  const auto& m = SaturatedTwin();
  MachineLimits lim = TwinLimits();
  TableSpec spec;
  spec.kind = "fw";
  spec.points = 19;             // round torques (2 N m apart for this motor)
  spec.speed_points = 8;
  spec.speed_max_rpm = 7000;   // well past the MTPV onset of this motor
  auto t = BuildTable(m, lim, spec);
  ASSERT_TRUE(t.ok()) << t.status();
  struct GridPoint { double id, iq, psi_d, psi_q; };
  std::vector<GridPoint> grid;
  for (double a = -lim.i_max_a; a <= 0; a += 0.25) {
    for (double b = -lim.i_max_a; b <= lim.i_max_a; b += 0.25) {
      if (std::hypot(a, b) > lim.i_max_a) continue;
      const auto f = m.Flux(a, b, lim.temperature_c);
      grid.push_back({a, b, f.psi_d_wb, f.psi_q_wb});
    }
  }
  const auto& tq = t->axes[0].values;
  const auto& rpm = t->axes[1].values;
  const double tmax = *std::max_element(tq.begin(), tq.end());
  int checked = 0, clamped = 0;
  for (size_t j = 0; j < rpm.size(); ++j) {
    const double we = rpm[j] * lim.pole_pairs * 2 * kPi / 60;
    std::vector<const GridPoint*> feasible;
    for (const auto& g : grid) {
      if (std::hypot(*lim.rs_ohm * g.id - we * g.psi_q, *lim.rs_ohm * g.iq + we * g.psi_d) <=
          lim.UMaxV())
        feasible.push_back(&g);
    }
    for (size_t i = 0; i < tq.size(); ++i) {
      if (std::abs(tq[i]) < 0.05 * tmax) continue;
      const size_t cell = i * rpm.size() + j;
      const double id = t->outputs[0].values[cell], iq = t->outputs[1].values[cell];
      const double torque = TorqueNm(m, lim.pole_pairs, id, iq, lim.temperature_c);
      const double s = tq[i] < 0 ? -1.0 : 1.0;
      double least_current = 1e9, most_torque = 0;
      for (const GridPoint* g : feasible) {
        const double tg = 1.5 * lim.pole_pairs * (g->psi_d * g->iq - g->psi_q * g->id);
        most_torque = std::max(most_torque, s * tg);
        if (std::abs(tg - tq[i]) < 5e-4 * std::abs(tq[i]))
          least_current = std::min(least_current, std::hypot(g->id, g->iq));
      }
      if (t->clamped[cell]) {
        EXPECT_GE(s * torque, most_torque * (1 - 1e-3))
            << "clamped cell " << tq[i] << " N m at " << rpm[j] << " rpm";
      } else {
        ASSERT_LT(least_current, 1e9) << "brute force found no point for " << tq[i] << " N m";
        EXPECT_LE(std::hypot(id, iq), least_current * 1.001)
            << "cell " << tq[i] << " N m at " << rpm[j] << " rpm";
      }
      ++checked;
      clamped += t->clamped[cell];
    }
  }
  EXPECT_GT(checked, 50);
  EXPECT_GT(clamped, 10);             // the limit-torque side is exercised
  EXPECT_GT(checked - clamped, 10);   // and the least-current side
}

// MTPV: on each flux circle |psi| = psi_k the table's point delivers the
// largest torque (brute force over id on the circle).
TEST(Mtpv, MaximumTorquePerFluxByBruteForce) {
  const auto& m = SaturatedTwin();
  MachineLimits lim = TwinLimits();
  TableSpec spec;
  spec.kind = "mtpv";
  spec.points = 9;
  auto t = BuildTable(m, lim, spec);
  ASSERT_TRUE(t.ok());
  int checked = 0;
  for (size_t k = 0; k < t->axes[0].values.size(); ++k) {
    if (t->clamped[k]) continue;   // beyond the current limit
    ++checked;
    const double lam = t->axes[0].values[k];
    double best = 0;
    for (double id = -300; id <= 0; id += 0.25) {
      // iq on the circle by bisection (|psi| grows with iq).
      double lo = 0, hi = 600;
      auto mag = [&](double q) { const auto f = m.Flux(id, q); return std::hypot(f.psi_d_wb, f.psi_q_wb); };
      if (mag(lo) > lam || mag(hi) < lam) continue;
      for (int it = 0; it < 60; ++it) { const double mid = 0.5 * (lo + hi); (mag(mid) < lam ? lo : hi) = mid; }
      best = std::max(best, TorqueNm(m, 4, id, lo));
    }
    EXPECT_GE(t->outputs[2].values[k], best * (1 - 1e-3)) << "row " << k << " psi " << lam;
  }
  EXPECT_GE(checked, 2) << "rows inside the current limit";
}

// Using the differential inductance as apparent gives a measurably worse
// MTPA table on a saturated motor: the torque it delivers is wrong.
TEST(Mtpa, DifferentialAsApparentIsWorse) {
  const auto& m = SaturatedTwin();
  DifferentialAsApparent wrong(m);
  MachineLimits lim = TwinLimits();
  TableSpec spec;
  spec.points = 9;
  spec.include_generating = false;
  auto good = BuildTable(m, lim, spec);
  auto bad = BuildTable(wrong, lim, spec);
  ASSERT_TRUE(good.ok() && bad.ok());
  double worst = 0, tmax = good->axes[0].values.back();
  for (size_t k = 1; k < bad->axes[0].values.size(); ++k) {
    const double delivered = TorqueNm(m, 4, bad->outputs[0].values[k], bad->outputs[1].values[k]);
    worst = std::max(worst, std::abs(delivered - bad->axes[0].values[k]) / tmax);
  }
  std::printf("differential-as-apparent MTPA: worst torque error %.2f %% of the maximum\n", 100 * worst);
  EXPECT_GT(worst, 0.02);
}

Table SmallTable(const std::string& kind) {
  return *BuildTable(SaturatedTwin(), TwinLimits(), SmallLabelledSpec(kind, 3000));
}

std::vector<double> Numbers(const std::string& s) {
  std::vector<double> v;
  std::istringstream in(s);
  double x;
  while (in >> x) v.push_back(x);
  return v;
}

TEST(Export, CsvRoundTrip) {
  const Table t = SmallTable("fw");
  auto e = Export(t, Format::kCsv);
  ASSERT_TRUE(e.ok());
  std::istringstream in(e->bytes);
  std::string line;
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line[0] == 't') continue;
    for (auto& c : line) if (c == ',') c = ' ';
    rows.push_back(Numbers(line));
  }
  // One row per cell: at most 5 round torques x 4 round speeds.
  ASSERT_EQ(rows.size(), t.axes[0].values.size() * t.axes[1].values.size());
  ASSERT_GE(rows.size(), 6u);
  for (size_t r = 0; r < rows.size(); ++r) {
    EXPECT_EQ(rows[r][2], t.outputs[0].values[r]);
    EXPECT_EQ(rows[r][3], t.outputs[1].values[r]);
  }
}

TEST(Export, JsonRoundTrip) {
  const Table t = SmallTable("mtpa");
  auto e = Export(t, Format::kJson);
  ASSERT_TRUE(e.ok());
  const auto j = nlohmann::json::parse(e->bytes);
  EXPECT_EQ(j["outputs"][0]["values"].get<std::vector<double>>(), t.outputs[0].values);
  EXPECT_EQ(j["payload_sha256"], t.sha256);
  // The checksum a flashing station recomputes from the parsed values.
  Table back = t;
  back.outputs[0].values = j["outputs"][0]["values"].get<std::vector<double>>();
  Seal(&back);
  EXPECT_EQ(back.sha256, t.sha256);
}

TEST(Export, CHeaderRoundTrip) {
  const Table t = SmallTable("mtpa");
  auto e = Export(t, Format::kCHeader);
  ASSERT_TRUE(e.ok());
  std::smatch m;
  const std::regex arr("static const double fluxcal_mtpa_id_a\\[(\\d+)\\] = \\{([^}]*)\\}");
  ASSERT_TRUE(std::regex_search(e->bytes, m, arr));
  std::string body = m[2];
  for (auto& c : body) if (c == ',') c = ' ';
  EXPECT_EQ(Numbers(body), t.outputs[0].values);
  EXPECT_NE(e->bytes.find(t.sha256), std::string::npos);
}

// The header as an ECU build would use it: compiled by the system C
// compiler in strict C99 with warnings as errors, and the program's printout
// of every array, the CRC and the SHA-256 compared with the table.
TEST(Export, CHeaderCompilesAsC99AndCarriesTheValues) {
  if (std::system("cc --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "no C compiler (cc)";
  const Table t = SmallTable("fw");
  auto e = Export(t, Format::kCHeader);
  ASSERT_TRUE(e.ok());
  std::string prog = "#include <stdio.h>\n#include \"table.h\"\nint main(void) {\n  int k;\n";
  std::vector<std::vector<double>> want;
  ForEachArray(t, [&](const std::string& name, const std::vector<double>& v) {
    const std::string lower = "fluxcal_fw_" + name, upper = "FLUXCAL_FW_" + absl::AsciiStrToUpper(name);
    prog += "  for (k = 0; k < " + upper + "_LEN; ++k) printf(\"%.17g\\n\", " + lower + "[k]);\n";
    want.push_back(v);
  });
  prog += "  printf(\"%08lx %s\\n\", (unsigned long)fluxcal_fw_payload_crc32, fluxcal_fw_payload_sha256);\n  return 0;\n}\n";
  std::string printed;
  ASSERT_NO_FATAL_FAILURE(BuildAndRunC99("fluxcal_c_header", {{"table.h", e->bytes}}, prog, "",
                                         "compiling the exported header failed", &printed));
  std::istringstream in(printed);
  for (const auto& v : want) {
    for (double x : v) {
      double got;
      ASSERT_TRUE(in >> got);
      EXPECT_EQ(got, x);   // %.17g round-trips a double exactly
    }
  }
  std::string crc, sha;
  ASSERT_TRUE(in >> crc >> sha);
  EXPECT_EQ(crc, absl::StrFormat("%08x", t.crc32));
  EXPECT_EQ(sha, t.sha256);
}

// Reading a plot back: elements by class, the axes' data-to-pixel maps
// from their own tick labels, path coordinates.
void Walk(const tinyxml2::XMLElement* e, const std::function<void(const tinyxml2::XMLElement*)>& f) {
  for (auto* c = e->FirstChildElement(); c; c = c->NextSiblingElement()) {
    f(c);
    Walk(c, f);
  }
}
std::vector<const tinyxml2::XMLElement*> ByClass(const tinyxml2::XMLElement* root, const std::string& cls) {
  std::vector<const tinyxml2::XMLElement*> out;
  Walk(root, [&](const tinyxml2::XMLElement* e) {
    if (e->Attribute("class") && cls == e->Attribute("class")) out.push_back(e);
  });
  return out;
}
std::vector<std::string> TextsIn(const tinyxml2::XMLElement* g) {
  std::vector<std::string> out;
  Walk(g, [&](const tinyxml2::XMLElement* e) {
    if (std::string(e->Name()) == "text" && e->GetText()) out.push_back(e->GetText());
  });
  return out;
}
// Pixel -> data along one axis, from the first and last tick label of the
// group ("xticks": label x is the tick; "yticks": label y is the tick + 4).
struct AxisMap {
  double a = 0, b = 0;   // value = a + b * px
  double operator()(double px) const { return a + b * px; }
};
AxisMap FromTicks(const tinyxml2::XMLElement* svg, bool x_axis) {
  std::vector<std::pair<double, double>> ticks;   // (px, value)
  const auto groups = ByClass(svg, x_axis ? "xticks" : "yticks");
  EXPECT_EQ(groups.size(), 1u);
  if (groups.empty()) return {};
  Walk(groups[0], [&](const tinyxml2::XMLElement* e) {
    if (std::string(e->Name()) != "text") return;
    ticks.push_back({x_axis ? e->DoubleAttribute("x") : e->DoubleAttribute("y") - 4, std::stod(e->GetText())});
  });
  EXPECT_GE(ticks.size(), 3u);
  if (ticks.size() < 2) return {};
  AxisMap m;
  m.b = (ticks.back().second - ticks.front().second) / (ticks.back().first - ticks.front().first);
  m.a = ticks.front().second - m.b * ticks.front().first;
  return m;
}
std::vector<std::pair<double, double>> PathPoints(const char* d) {
  std::vector<std::pair<double, double>> out;
  std::string s(d);
  for (auto& c : s) if (c == 'M' || c == 'L') c = ' ';
  std::istringstream in(s);
  double x, y;
  while (in >> x >> y) out.push_back({x, y});
  return out;
}

// The plots are well-formed SVG (an XML parser reads them) and draw the
// tables' data, read back through the axes' own tick labels: the MTPA and
// MTPV lines map back to the tables' motoring rows, the current-limit
// circle lies on |i| = i_max and the voltage limit on |u| = u_max at the
// speed its legend names; every line has a legend entry. The heat map has
// one cell per table entry at its speed and torque, coloured as the colour
// bar (whose labels are round ticks from end to end) shows its value, and
// one cross per clamped cell.
TEST(Plots, SvgParsesAndDrawsTheTables) {
  const auto& m = SaturatedTwin();
  MachineLimits lim = TwinLimits();
  TableSpec spec;
  spec.points = 9;
  auto mtpa = BuildTable(m, lim, spec);
  ASSERT_TRUE(mtpa.ok());
  spec.kind = "mtpv";
  spec.allow_extrapolation = true;
  auto mtpv = BuildTable(m, lim, spec);
  ASSERT_TRUE(mtpv.ok()) << mtpv.status();
  auto rows_of = [](const Table& t) {
    std::vector<std::pair<double, double>> rows;
    for (size_t k = 0; k < t.outputs[0].values.size(); ++k) {
      if (t.outputs[1].values[k] < 0) continue;
      // MTPV rows the solver could not place (no torque, id at its search
      // bound of -2 i_max) are not points of the curve.
      if (t.kind == "mtpv" && (!(t.outputs[2].values[k] > 0) || t.outputs[0].values[k] < -1.99 * t.limits.i_max_a)) {
        continue;
      }
      rows.push_back({t.outputs[0].values[k], t.outputs[1].values[k]});
    }
    return rows;
  };
  // Each table's figure: both curves, the subject bold with a dot per row.
  for (const bool mtpv_subject : {false, true}) {
    SCOPED_TRACE(mtpv_subject ? "MTPV figure" : "MTPA figure");
    const std::string curves = mtpv_subject ? PlotMtpvSvg(m, lim, *mtpv, &*mtpa) : PlotCurvesSvg(m, lim, *mtpa, &*mtpv);
    tinyxml2::XMLDocument doc;
    ASSERT_EQ(doc.Parse(curves.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
    const tinyxml2::XMLElement* svg = doc.RootElement();
    ASSERT_STREQ(svg->Name(), "svg");
    const AxisMap id_of = FromTicks(svg, true), iq_of = FromTicks(svg, false);
    const auto legend = ByClass(svg, "legend");
    ASSERT_EQ(legend.size(), 1u);
    const auto labels = TextsIn(legend[0]);
    auto label_with = [&](const std::string& start) {
      for (const auto& l : labels) if (l.rfind(start, 0) == 0) return l;
      return std::string();
    };
    double rpm = 0;
    ASSERT_EQ(std::sscanf(label_with("voltage limit").c_str(), "voltage limit |u| = %*f V at %lf rpm", &rpm), 1)
        << "the voltage limit's legend entry names its speed";
    const double we = rpm * lim.pole_pairs * 2 * std::numbers::pi / 60;
    EXPECT_FALSE(label_with("current limit |i| = 150 A").empty());
    EXPECT_FALSE(label_with("constant torque").empty());
    const std::string subject = mtpv_subject ? "MTPV table" : "MTPA table";
    const std::string other = mtpv_subject ? "MTPA table" : "MTPV table";
    EXPECT_FALSE(label_with(subject).empty());
    EXPECT_NE(label_with(other).find("for reference"), std::string::npos);
    bool saw_mtpa = false, saw_mtpv = false, saw_limit = false, saw_voltage = false;
    std::map<std::string, double> width;
    for (const auto* e : ByClass(svg, "line")) {
      const std::string stroke = e->Attribute("stroke");
      const auto pts = PathPoints(e->Attribute("d"));
      if (stroke == "#d62728" || stroke == "#1f77b4") {
        const bool is_mtpa = stroke == "#d62728";
        (is_mtpa ? saw_mtpa : saw_mtpv) = true;
        width[stroke] = e->DoubleAttribute("stroke-width");
        const auto rows = rows_of(is_mtpa ? *mtpa : *mtpv);
        ASSERT_EQ(pts.size(), rows.size()) << stroke;
        for (size_t k = 0; k < pts.size(); ++k) {
          EXPECT_NEAR(id_of(pts[k].first), rows[k].first, 0.5) << stroke << " point " << k;
          EXPECT_NEAR(iq_of(pts[k].second), rows[k].second, 0.5) << stroke << " point " << k;
        }
      }
      if (stroke == "#000000" && e->Attribute("stroke-dasharray")) {
        saw_limit = true;
        for (const auto& p : pts) EXPECT_NEAR(std::hypot(id_of(p.first), iq_of(p.second)), lim.i_max_a, 0.5);
      }
    }
    std::vector<std::pair<double, double>> ellipse;
    for (const auto* e : ByClass(svg, "contour")) {
      if (std::string(e->Attribute("stroke")) != "#ff7f0e") continue;
      saw_voltage = true;
      for (const auto& p : PathPoints(e->Attribute("d"))) {
        ellipse.push_back({id_of(p.first), iq_of(p.second)});
        EXPECT_NEAR(VoltageV(m, lim, ellipse.back().first, ellipse.back().second, we) / lim.UMaxV(), 1.0, 0.02);
      }
    }
    EXPECT_TRUE(saw_mtpa);
    EXPECT_TRUE(saw_mtpv);
    EXPECT_TRUE(saw_limit);
    EXPECT_TRUE(saw_voltage);
    const std::string bold = mtpv_subject ? "#1f77b4" : "#d62728", thin = mtpv_subject ? "#d62728" : "#1f77b4";
    EXPECT_GT(width[bold], width[thin]) << "the subject drawn bold";
    // Every row of the subject a dot in its colour; none on the other.
    std::map<std::string, size_t> dots;
    for (const auto* e : ByClass(svg, "point")) {
      if (std::string(e->Name()) == "circle") ++dots[e->Attribute("fill")];
    }
    EXPECT_EQ(dots[bold], rows_of(mtpv_subject ? *mtpv : *mtpa).size());
    EXPECT_EQ(dots[thin], 0u);
    if (mtpv_subject) {
      // MTPV operation begins where the voltage limit reaches the MTPV row
      // of largest current inside the current limit: the drawn limit
      // passes through that row.
      std::pair<double, double> start{0, 0};
      for (const auto& r : rows_of(*mtpv)) {
        const double i = std::hypot(r.first, r.second);
        if (i <= lim.i_max_a * (1 + 1e-9) && i > std::hypot(start.first, start.second)) start = r;
      }
      // Distance to the drawn segments (vertices lie a grid step apart).
      double nearest = 1e9;
      for (size_t k = 1; k < ellipse.size(); ++k) {
        const auto [x0, y0] = ellipse[k - 1];
        const auto [x1, y1] = ellipse[k];
        const double dx = x1 - x0, dy = y1 - y0, len2 = dx * dx + dy * dy;
        if (len2 > 25) continue;   // a jump between two pieces of the contour
        const double t = len2 > 0 ? std::clamp(((start.first - x0) * dx + (start.second - y0) * dy) / len2, 0.0, 1.0) : 0;
        nearest = std::min(nearest, std::hypot(start.first - x0 - t * dx, start.second - y0 - t * dy));
      }
      EXPECT_LT(nearest, 0.5) << "the voltage limit misses the MTPV start (" << start.first << ", " << start.second << ")";
    }
  }

  const Table fw = SmallTable("fw");
  const std::string map = PlotMapSvg(fw, "id_a");
  tinyxml2::XMLDocument mdoc;
  ASSERT_EQ(mdoc.Parse(map.c_str()), tinyxml2::XML_SUCCESS) << mdoc.ErrorStr();
  const auto* msvg = mdoc.RootElement();
  const auto& v = fw.outputs[0].values;
  const size_t n1 = fw.axes[1].values.size();
  const auto bar = ByClass(msvg, "colourbar");
  ASSERT_EQ(bar.size(), 1u);
  auto ticks = TextsIn(bar[0]);
  ASSERT_GE(ticks.size(), 4u);
  EXPECT_EQ(ticks.back(), "id [A]");
  ticks.pop_back();
  const double lo = std::stod(ticks.front()), hi = std::stod(ticks.back());
  EXPECT_LE(lo, *std::min_element(v.begin(), v.end()));
  EXPECT_GE(hi, *std::max_element(v.begin(), v.end()));
  const double step = std::stod(ticks[1]) - lo;
  for (const auto& t : ticks) EXPECT_NEAR(std::stod(t) / step, std::round(std::stod(t) / step), 1e-6) << t;
  const AxisMap speed_of = FromTicks(msvg, true), torque_of = FromTicks(msvg, false);
  const double speed_span = fw.axes[1].values.back() - fw.axes[1].values.front();
  const double torque_span = fw.axes[0].values.back() - fw.axes[0].values.front();
  size_t cells = 0;
  for (const auto* e : ByClass(msvg, "cell")) {
    ASSERT_LT(cells, v.size());
    // Cells are written row-major over (torque, speed), like the table.
    EXPECT_EQ(std::string(e->Attribute("fill")), plot::ColourMap((v[cells] - lo) / (hi - lo))) << "cell " << cells;
    const double cx = e->DoubleAttribute("x") + e->DoubleAttribute("width") / 2;
    const double cy = e->DoubleAttribute("y") + e->DoubleAttribute("height") / 2;
    EXPECT_NEAR(speed_of(cx), fw.axes[1].values[cells % n1], 0.01 * speed_span) << "cell " << cells;
    EXPECT_NEAR(torque_of(cy), fw.axes[0].values[cells / n1], 0.01 * torque_span) << "cell " << cells;
    ++cells;
  }
  EXPECT_EQ(cells, v.size());
  size_t clamped = 0, crosses = 0;
  for (auto c : fw.clamped) clamped += c;
  for (const auto* e : ByClass(msvg, "point")) crosses += std::string(e->Name()) == "path";
  EXPECT_EQ(crosses, clamped) << "one cross per clamped cell, drawn unlike valid cells";
}

TEST(Export, CdfxRoundTripThroughXmlParser) {
  const Table t = SmallTable("fw");
  auto e = Export(t, Format::kCdfx);
  ASSERT_TRUE(e.ok());
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(e->bytes.c_str()), tinyxml2::XML_SUCCESS);
  auto* tree = doc.FirstChildElement("MSRSW")->FirstChildElement("SW-SYSTEMS")->FirstChildElement("SW-SYSTEM")
                   ->FirstChildElement("SW-INSTANCE-SPEC")->FirstChildElement("SW-INSTANCE-TREE");
  ASSERT_NE(tree, nullptr);
  auto* inst = tree->FirstChildElement("SW-INSTANCE");
  while (inst && std::string(inst->FirstChildElement("SHORT-NAME")->GetText()) != "FLUXCAL_FW_ID_A") {
    inst = inst->NextSiblingElement("SW-INSTANCE");
  }
  ASSERT_NE(inst, nullptr);
  EXPECT_STREQ(inst->FirstChildElement("CATEGORY")->GetText(), "MAP");
  std::vector<double> vals;
  for (auto* vg = inst->FirstChildElement("SW-VALUE-CONT")->FirstChildElement("SW-VALUES-PHYS")->FirstChildElement("VG");
       vg; vg = vg->NextSiblingElement("VG")) {
    for (auto* v = vg->FirstChildElement("V"); v; v = v->NextSiblingElement("V")) vals.push_back(std::stod(v->GetText()));
  }
  EXPECT_EQ(vals, t.outputs[0].values);
}

TEST(Export, DcmRoundTrip) {
  for (const char* kind : {"mtpa", "fw"}) {
    const Table t = SmallTable(kind);
    auto e = Export(t, Format::kDcm);
    ASSERT_TRUE(e.ok());
    // Minimal DCM reader: block header, ST/X, ST/Y, WERT until END.
    std::istringstream in(e->bytes);
    std::string line, name;
    std::map<std::string, std::vector<double>> wert, stx;
    while (std::getline(in, line)) {
      std::istringstream ls(line);
      std::string key;
      ls >> key;
      if (key == "KENNLINIE" || key == "KENNFELD") ls >> name;
      else if (key == "WERT") { double x; while (ls >> x) wert[name].push_back(x); }
      else if (key == "ST/X") { double x; while (ls >> x) stx[name].push_back(x); }
    }
    const std::string id = std::string("FLUXCAL_") + (std::string(kind) == "fw" ? "FW" : "MTPA") + "_ID_A";
    // X = the first axis (torque) in every format; a KENNFELD lists, per Y
    // (speed) value, the WERT values over X.
    const size_t n0 = t.axes[0].values.size(), n1 = t.axes.size() > 1 ? t.axes[1].values.size() : 1;
    std::vector<double> want;
    for (size_t j = 0; j < n1; ++j)
      for (size_t i = 0; i < n0; ++i) want.push_back(t.outputs[0].values[i * n1 + j]);
    EXPECT_EQ(wert[id], want) << kind;
    EXPECT_EQ(stx[id], t.axes.front().values) << kind;
  }
}

}  // namespace
TEST(Signature, SignVerifyTamperWrongKeyMalformed) {
  auto a = GenerateEd25519();
  auto b = GenerateEd25519();
  ASSERT_TRUE(a.ok() && b.ok());
  const std::string data = "KENNLINIE FLUXCAL_MTPA_ID_A 16\n";
  auto sig = SignDetached(data, a->private_pem);
  ASSERT_TRUE(sig.ok()) << sig.status();
  EXPECT_EQ(sig->rfind("fluxcal-signature-v1 ed25519\nkey_id ", 0), 0u);
  EXPECT_TRUE(VerifyDetached(data, *sig, a->public_pem).ok());
  EXPECT_EQ(VerifyDetached(data + " ", *sig, a->public_pem).code(), absl::StatusCode::kPermissionDenied);
  EXPECT_EQ(VerifyDetached(data, *sig, b->public_pem).code(), absl::StatusCode::kPermissionDenied);
  // A forged signature line with the right key id and digest.
  std::string forged = *sig;
  const auto pos = forged.find("signature ") + 10;
  forged[pos] = forged[pos] == 'A' ? 'B' : 'A';
  EXPECT_EQ(VerifyDetached(data, forged, a->public_pem).code(), absl::StatusCode::kPermissionDenied);
  EXPECT_EQ(VerifyDetached(data, "garbage", a->public_pem).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(VerifyDetached(data, *sig, "not a key").code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(*PublicPemOf(a->private_pem), a->public_pem);
  EXPECT_EQ(KeyId(a->public_pem)->size(), 16u);
  EXPECT_NE(*KeyId(a->public_pem), *KeyId(b->public_pem));
}

}  // namespace fluxcal::tables
