// The report page against its sources: the table checksums it prints are
// the tables library's for the same limits, the limits say where they came
// from, the measured points are drawn over the surfaces, the half of the
// current plane nobody measured is drawn and marked (extrapolated, or by
// symmetry), the positive-definite check says where it fails, every
// number is rounded, a bad diagnosis document is refused naming file and
// field, and text from the inputs is escaped. Fixture: the public Baldor
// EOL set (a real machine measured in the motoring half only; data/real),
// fitted here.
#include "report/report.h"

#include <gtest/gtest.h>

#include <initializer_list>
#include <regex>

#include "absl/strings/str_format.h"
#include "fitting/fit.h"
#include "identification/identify.h"
#include "io/flux_map.h"
#include "io/recording_set.h"
#include "plot/plot.h"
#include "tables/tables.h"

namespace fluxcal::report {
namespace {

// Each of `parts` stands in the page (one expectation each).
void ExpectInPage(const std::string& html, std::initializer_list<const char*> parts) {
  for (const char* part : parts) EXPECT_NE(html.find(part), std::string::npos) << part;
}

size_t Count(const std::string& s, const std::string& what) {
  size_t n = 0;
  for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
  return n;
}

// The SVG of one figure of the page (empty when absent).
std::string FigureSvg(const std::string& html, const std::string& id) {
  const size_t a = html.find("id=\"" + id + "\"");
  return a == std::string::npos ? std::string() : html.substr(a, html.find("</svg>", a) - a);
}

// What a reader sees: the page without its style sheet and tags, entities
// of the escaper undone.
std::string VisibleText(const std::string& html) {
  std::string s;
  for (size_t i = 0; i < html.size();) {
    if (html.compare(i, 7, "<style>") == 0) {
      const size_t end = html.find("</style>", i);
      i = end == std::string::npos ? html.size() : end + 8;
    } else if (html[i] == '<') {
      const size_t end = html.find('>', i);
      i = end == std::string::npos ? html.size() : end + 1;
      s += ' ';
    } else {
      s += html[i++];
    }
  }
  for (const auto& [from, to] : {std::pair<std::string, std::string>{"&lt;", "<"}, {"&gt;", ">"}, {"&quot;", "\""},
                                 {"&amp;", "&"}}) {
    for (size_t at = s.find(from); at != std::string::npos; at = s.find(from, at)) s.replace(at, from.size(), to);
  }
  return s;
}

// Every number a reader sees is rounded: no five decimals and more, no
// "-0" (the issue's "0.02556 A", "-0 A").
void ExpectRounded(const std::string& html, const std::string& what) {
  const std::string text = VisibleText(html);
  std::smatch m;
  EXPECT_FALSE(std::regex_search(text, m, std::regex(R"(\d\.\d{5,})")))
      << what << ": unrounded number '" << m.str() << "' in: ..." << m.prefix().str().substr(
             std::max<size_t>(m.prefix().length(), 60) - 60) << m.str() << "...";
  EXPECT_FALSE(std::regex_search(text, m, std::regex(R"((^|[^\w.])-0([^\w.]|$))")))
      << what << ": a '-0' in: ..." << m.prefix().str().substr(std::max<size_t>(m.prefix().length(), 60) - 60)
      << m.str() << "...";
}

class ReportTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const std::string dir = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol";
    auto set = io::ReadRecordingSet(dir);
    ASSERT_TRUE(set.ok()) << set.status();
    // As `fluxcal fit SET` and `report --set` take it: the bench's HF
    // results and its steady-state rows.
    data_ = new fit::FitData(fit::FitDataFromRecording(*set, {}));
    auto cal = fit::Fit(*data_);
    ASSERT_TRUE(cal.ok()) << cal.status();
    cal_ = new fit::Calibration(*cal);
    // Without Udc the page has no field-weakening table (the slow part):
    // the tests of the surfaces, the plane and the diagnosis use it.
    cal_no_udc_ = new fit::Calibration(*cal);
    cal_no_udc_->set_udc_v(std::nullopt);
    // The two full pages most tests read, built once: the calibration as
    // it is, and with the set's points, a given Udc and a diagnosis whose
    // numbers carry every digit of a double.
    auto plain = BuildReport(Inputs());
    ASSERT_TRUE(plain.ok()) << plain.status();
    plain_ = new Report(*plain);
    ReportInputs in = Inputs();
    in.identified = data_;
    in.udc_v = 540.0;
    in.udc_source = "test: 540 V";
    in.diagnosis = nlohmann::json::parse(R"({"format": "fluxcal.diagnosis.v1", "serial": "X", "verdict": "explained",
      "baseline": {"model": "nominal", "residual_rms": 0.3413123, "bic": 2490.123456},
      "mismatches": [{"signal": "dc_voltage", "where": "low current, |i| < 25.123456 A", "points": ["p031"],
                      "significance_sigma": 29920.5123}],
      "findings": [{"effect": "dead_time", "explanation": "a drop of 0.1234567 V",
      "parameters": {"dead_time_s": 2.5076234e-6}, "parameter_std": {"dead_time_s": 1.349e-9},
      "residual_rms_before": 0.3413123, "residual_rms_after": 0.001372123, "delta_bic": -3240.51234}],
      "final": {"model": "nominal+dead_time", "residual_rms": 0.001372123, "bic": -750.3123}})");
    in.diagnosis_path = "diag.json";
    auto points = BuildReport(in);
    ASSERT_TRUE(points.ok()) << points.status();
    points_ = new Report(*points);
  }
  static ReportInputs Inputs(const fit::Calibration* cal = nullptr) {
    ReportInputs in;
    in.calibration = cal != nullptr ? cal : cal_;
    in.calibration_json = in.calibration->ToJson();
    in.calibration_path = "baldor.json";
    in.software_version = "test";
    return in;
  }
  static fit::FitData* data_;
  static fit::Calibration* cal_;
  static fit::Calibration* cal_no_udc_;
  static Report* plain_;    // Inputs()
  static Report* points_;   // with the set's points, Udc 540 V given, a diagnosis
};
fit::FitData* ReportTest::data_ = nullptr;
fit::Calibration* ReportTest::cal_ = nullptr;
fit::Calibration* ReportTest::cal_no_udc_ = nullptr;
Report* ReportTest::plain_ = nullptr;
Report* ReportTest::points_ = nullptr;

TEST_F(ReportTest, ChecksumsAreTheTablesLibrarys) {
  const Report* rep = points_;
  // Five surfaces, the current plane, the envelope's torque and power, the
  // two field-weakening maps.
  EXPECT_EQ(rep->figures, 10);
  EXPECT_EQ(Count(rep->html, "<svg "), 10u);
  tables::MachineLimits lim;
  lim.pole_pairs = cal_->pole_pairs();
  lim.rs_ohm = cal_->rs_ohm();
  lim.i_max_a = cal_->MeasuredCurrentLimitA();
  lim.udc_v = 540.0;
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    tables::TableSpec spec;
    spec.kind = kind;
    spec.measured_current_limit_a = cal_->MeasuredCurrentLimitA();
    auto t = tables::BuildTable(*cal_, lim, spec);
    if (!t.ok() && absl::IsFailedPrecondition(t.status())) {
      // As the page does: an MTPV wholly beyond the measured limit is drawn
      // extrapolated (flagged), the export refuses it without the flag.
      spec.allow_extrapolation = true;
      t = tables::BuildTable(*cal_, lim, spec);
      EXPECT_NE(rep->html.find("MTPV curve lies beyond the measured current limit"), std::string::npos);
    }
    ASSERT_TRUE(t.ok()) << t.status();
    EXPECT_NE(rep->html.find(absl::StrFormat("<code>%08x</code>", t->crc32)), std::string::npos)
        << kind << ": expected crc32 " << absl::StrFormat("%08x", t->crc32) << " on the page";
    EXPECT_NE(rep->html.find(t->sha256), std::string::npos) << kind << ": sha256 " << t->sha256;
  }
  EXPECT_NE(rep->html.find("test: 540 V"), std::string::npos) << "Udc's source is said";
  EXPECT_EQ(rep->html.find("class=\"warn\""), std::string::npos)
      << "540 V is above the resistive drop: no limits warning expected";
  EXPECT_GT(rep->ellipse_speed_rpm, 0.0);
}

TEST_F(ReportTest, UdcBelowResistiveDropIsWarned) {
  // Rs 3.6 ohm x 18 A is far above 50 V / sqrt 3: a Udc that does not fit
  // this machine, and the page has to say so and where it came from.
  ReportInputs in = Inputs();
  in.udc_v = 50.0;
  in.udc_source = "test: 50 V";
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  ExpectInPage(rep->html, {"class=\"warn\"", "below the resistive drop", "test: 50 V"});
}

// Without --udc-v or a set, Udc is the calibration's (the Baldor set's
// manifest says 540 V); never a default of some other drive.
TEST_F(ReportTest, UdcFromTheCalibration) {
  ASSERT_TRUE(cal_->udc_v().has_value());
  EXPECT_EQ(*cal_->udc_v(), 540.0);
  const Report* rep = plain_;
  EXPECT_EQ(rep->figures, 10);
  EXPECT_NE(rep->html.find("540 V <small>(the calibration"), std::string::npos) << "Udc and its source on the page";
  EXPECT_EQ(rep->html.find("class=\"warn\""), std::string::npos) << "540 V fits this machine";
  EXPECT_GT(rep->ellipse_speed_rpm, 0.0);
}

// Udc known nowhere: the page says the voltage limit, the envelope and
// field weakening cannot be drawn instead of drawing them at an assumed
// voltage (before, 50 V: a map clamped everywhere on a page that said
// pass). MTPA and MTPV need no Udc and are still there, checksums as the
// tables library's.
TEST_F(ReportTest, UnknownUdcDrawsNoVoltageLimit) {
  const fit::Calibration& cal = *cal_no_udc_;
  auto rep = BuildReport(Inputs(&cal));
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_NE(rep->html.find("The voltage limit and the field-weakening map cannot be drawn"), std::string::npos);
  EXPECT_NE(rep->html.find("the DC-link voltage Udc is not known"), std::string::npos);
  EXPECT_EQ(rep->html.find("id=\"fig-fw-"), std::string::npos) << "no field-weakening figure without Udc";
  EXPECT_EQ(rep->html.find("id=\"fig-envelope-"), std::string::npos) << "no envelope without Udc";
  EXPECT_EQ(rep->figures, 6) << "five surfaces and the current plane";
  EXPECT_EQ(rep->ellipse_speed_rpm, 0.0);
  EXPECT_EQ(rep->html.find("|u| ="), std::string::npos) << "no voltage-limit curve";
  EXPECT_NE(rep->html.find("<tr><td>fw</td><td colspan=\"9\">not computed"), std::string::npos);
  tables::MachineLimits lim;
  lim.pole_pairs = cal.pole_pairs();
  lim.rs_ohm = cal.rs_ohm();
  lim.i_max_a = cal.MeasuredCurrentLimitA();
  tables::TableSpec spec;
  spec.measured_current_limit_a = cal.MeasuredCurrentLimitA();
  auto mtpa = tables::BuildTable(cal, lim, spec);
  ASSERT_TRUE(mtpa.ok()) << mtpa.status();
  EXPECT_NE(rep->html.find(mtpa->sha256), std::string::npos) << "the MTPA table needs no Udc";
}

TEST_F(ReportTest, IdentifiedPointsAreDrawn) {
  const Report* rep = points_;
  // Ldd, Lqq and Ldq each draw every identified point that has the value
  // (six id levels: all of them have a curve), plus one legend dot.
  size_t with_ldq = 0;
  for (const auto& o : data_->inductances) with_ldq += o.ldq_h.has_value();
  EXPECT_EQ(Count(FigureSvg(rep->html, "fig-ldd"), "<circle "), data_->inductances.size() + 1);
  EXPECT_EQ(Count(FigureSvg(rep->html, "fig-lqq"), "<circle "), data_->inductances.size() + 1);
  EXPECT_EQ(Count(FigureSvg(rep->html, "fig-ldq"), "<circle "), with_ldq + (with_ldq > 0 ? 1 : 0));
}

// The steady-state rows measure flux (fit::SteadyStateFlux): each of them
// is a dot on psi_d (by its iq) and psi_q (by its id), in its line's
// colour, plus a legend dot.
TEST_F(ReportTest, SteadyStateFluxesAreDrawn) {
  ASSERT_EQ(data_->steady_state.size(), 9u);
  const Report* rep = points_;
  for (const char* fig : {"fig-psid", "fig-psiq"}) {
    const std::string svg = FigureSvg(rep->html, fig);
    EXPECT_EQ(Count(svg, "<circle "), data_->steady_state.size() + 1) << fig;
    EXPECT_NE(svg.find("steady-state rows"), std::string::npos) << fig;
  }
}

// A flux map's nodes over the surfaces (report --map): the nodes whose
// current is a curve's are drawn on psi_d and psi_q.
TEST_F(ReportTest, MapNodesAreDrawn) {
  auto map = io::ReadFluxMapCsv(std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_fluxmap_measured.csv");
  ASSERT_TRUE(map.ok()) << map.status();
  const fit::FitData nodes = fit::FitDataFromFluxMap(*map, cal_->pole_pairs());
  ReportInputs in = Inputs(cal_no_udc_);
  in.identified = &nodes;
  in.map_path = "baldor_fluxmap_measured.csv";
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  for (const char* fig : {"fig-psid", "fig-psiq"}) {
    const std::string svg = FigureSvg(rep->html, fig);
    // Six curves of 21 (id) or 27 (iq) nodes each lie on the map's grid.
    EXPECT_GE(Count(svg, "<circle "), 6u * 21u) << fig;
    EXPECT_NE(svg.find("flux map nodes"), std::string::npos) << fig;
  }
  // The map covers both signs of iq.
  EXPECT_NE(rep->html.find("Both halves measured"), std::string::npos);
}

// The Baldor set measured iq >= 0 only; a model asked for as smooth-asym is not
// symmetric in iq: the generating half, which the MTPA and field-weakening
// tables use, is drawn and marked extrapolated (dotted), with and without
// the set's points (without: from the asymmetric spline's knot span).
TEST_F(ReportTest, GeneratingHalfOfAOneSidedAsymmetricFitIsExtrapolated) {
  // One-sided data fit a symmetric family by default (fit::Fit); the
  // asymmetric one is asked for by name, as `fluxcal fit --model smooth-asym`.
  fit::FitOptions o;
  o.model = "smooth-asym";
  auto cal = fit::Fit(*data_, o);
  ASSERT_TRUE(cal.ok()) << cal.status();
  ASSERT_EQ(cal->family().Name(), "smooth-asym");
  for (bool with_points : {true, false}) {
    ReportInputs in = Inputs(&*cal);
    if (with_points) in.identified = data_;
    auto built = BuildReport(in);
    ASSERT_TRUE(built.ok()) << built.status();
    const Report* rep = &*built;
    EXPECT_NE(rep->html.find("iq &lt; 0 (generating): extrapolated"), std::string::npos) << with_points;
    const std::string plane = FigureSvg(rep->html, "fig-plane");
    // The MTPA's generating rows (red) and the MTPV (blue, beyond the
    // measured current limit) dotted; the legend says what dotted means.
    EXPECT_NE(plane.find("stroke=\"#d62728\" stroke-width=\"2.5\" stroke-dasharray=\"2 3\""), std::string::npos);
    EXPECT_NE(plane.find("stroke=\"#d62728\" stroke-width=\"2.5\" stroke-linejoin"), std::string::npos)
        << "the measured motoring half solid";
    EXPECT_NE(plane.find("stroke=\"#1f77b4\" stroke-width=\"2.5\" stroke-dasharray=\"2 3\""), std::string::npos);
    EXPECT_NE(plane.find("dotted: extrapolated, not measured"), std::string::npos);
    EXPECT_NE(plane.find("generating MTPV: not in the table"), std::string::npos);
    EXPECT_NE(FigureSvg(rep->html, "fig-fw-id_a").find("generating rows, extrapolated"), std::string::npos);
  }
}

// A model symmetric in iq (spline<R>) fitted to the same one-sided data: its
// generating half is the measured half mirrored, drawn dashed and said so;
// the generating MTPV is the table's rows mirrored.
TEST_F(ReportTest, GeneratingHalfOfASymmetricFitIsByMirror) {
  // (`--model smooth` weighs smooth-asym too; spline<R> is folded.)
  fit::FitOptions o;
  o.model = "spline";
  auto cal = fit::Fit(*data_, o);
  ASSERT_TRUE(cal.ok()) << cal.status();
  cal->set_udc_v(std::nullopt);   // the plane needs none; the page is quicker without the fw map
  ReportInputs in = Inputs(&*cal);
  in.identified = data_;
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_NE(rep->html.find("iq &lt; 0 (generating): by symmetry"), std::string::npos);
  const std::string plane = FigureSvg(rep->html, "fig-plane");
  EXPECT_NE(plane.find("stroke=\"#d62728\" stroke-width=\"2.5\" stroke-dasharray=\"8 4\""), std::string::npos);
  EXPECT_NE(plane.find("MTPV, generating: the table's rows mirrored"), std::string::npos);
  EXPECT_NE(plane.find("dashed: by symmetry (mirror of iq &gt; 0)"), std::string::npos);
}

// "positive definite over 1.5 x region: no" in bold under a pass badge was
// the issue: the page says where it fails and what that means.
TEST_F(ReportTest, PositiveDefiniteSaysWhere) {
  const Report* rep = plain_;
  EXPECT_EQ(rep->html.find("<b>no</b>"), std::string::npos);
  const size_t row = rep->html.find("<th>positive definite inductance</th>");
  ASSERT_NE(row, std::string::npos);
  const std::string text = rep->html.substr(row, rep->html.find("</tr>", row) - row);
  if (cal_->PhysicalOver(1.5)) {
    EXPECT_NE(text.find("yes, at all"), std::string::npos) << text;
  } else {
    // This fit's continuation is not physical beyond the measured region
    // (and only there): counted, located, and marked on the plane.
    EXPECT_NE(text.find("no, at "), std::string::npos) << text;
    EXPECT_NE(text.find("Of them 0 inside the measured region"), std::string::npos) << text;
    EXPECT_NE(text.find("the verdict judges the fit there and is not affected"), std::string::npos) << text;
    EXPECT_NE(FigureSvg(rep->html, "fig-plane").find("not positive definite ("), std::string::npos);
  }
  // The twin's analytic model is positive definite everywhere.
  fit::FitOptions o;
  o.model = "analytic";
  auto analytic = fit::Fit(*data_, o);
  ASSERT_TRUE(analytic.ok()) << analytic.status();
  analytic->set_udc_v(std::nullopt);
  auto rep2 = BuildReport(Inputs(&*analytic));
  ASSERT_TRUE(rep2.ok()) << rep2.status();
  const size_t row2 = rep2->html.find("<th>positive definite inductance</th>");
  ASSERT_NE(row2, std::string::npos);
  const std::string text2 = rep2->html.substr(row2, rep2->html.find("</tr>", row2) - row2);
  EXPECT_EQ(analytic->PhysicalOver(1.5), text2.find("yes, at all") != std::string::npos) << text2;
}

TEST_F(ReportTest, EveryNumberIsRounded) {
  const Report* rep = points_;
  ExpectRounded(rep->html, "Baldor page with points and a diagnosis");
  ExpectRounded(plain_->html, "Baldor page");
  EXPECT_NE(rep->html.find("dead_time_s = 2.5076 us ± 0.0013 us"), std::string::npos);
  EXPECT_NE(rep->html.find("|i| &lt; 25.1 A"), std::string::npos);
  // The measured region's id ends at 0, not "-0".
  EXPECT_NE(rep->html.find("id -18 .. 0 A"), std::string::npos);
}

TEST_F(ReportTest, DiagnosisFiguresAreEmbeddedWithTheirSource) {
  ReportInputs in = Inputs(cal_no_udc_);
  in.diagnosis = nlohmann::json{{"format", "fluxcal.diagnosis.v1"}, {"serial", "X"}, {"verdict", "explained"}};
  in.diagnosis_path = "diag.json";
  plot::Figure f("residual-test", 300, 200);
  f.Line({0, 1}, {0, 1}, plot::Style{}, "");
  in.diagnosis_figures = {{f.Svg(), "a residual map <of a test>"}};
  in.diagnosis_figures_note = "Residual maps: from a test.";
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_EQ(rep->figures, 7) << "five surfaces, the plane and the embedded one";
  ExpectInPage(rep->html, {"id=\"residual-test\"", "a residual map &lt;of a test&gt;", "Residual maps: from a test."});
}

TEST_F(ReportTest, DiagnosisOfTheWrongFormatNamesFileAndField) {
  ReportInputs in = Inputs(cal_no_udc_);
  in.diagnosis = nlohmann::json{{"format", "something.else"}};
  in.diagnosis_path = "diag.json";
  auto rep = BuildReport(in);
  ASSERT_FALSE(rep.ok());
  EXPECT_EQ(rep.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(rep.status().message().find("diag.json: field 'format'"), std::string::npos) << rep.status();
}

TEST_F(ReportTest, DiagnosisTextIsEscaped) {
  ReportInputs in = Inputs(cal_no_udc_);
  in.diagnosis = nlohmann::json::parse(R"({"format": "fluxcal.diagnosis.v1", "serial": "X", "verdict": "explained",
    "baseline": {"model": "nominal", "residual_rms": 0.041, "bic": 1234.5},
    "mismatches": [], "findings": [{"effect": "dead_time", "explanation": "<script>alert(1)</script>",
    "parameters": {"dead_time_s": 1.8e-6}, "parameter_std": {"dead_time_s": 0.1e-6},
    "residual_rms_before": 0.041, "residual_rms_after": 0.006, "delta_bic": -812.0}],
    "final": {"model": "nominal+dead_time", "residual_rms": 0.006, "bic": 422.5}})");
  in.diagnosis_path = "diag.json";
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_EQ(rep->html.find("<script"), std::string::npos);
  ExpectInPage(rep->html, {"&lt;script&gt;", "dead_time_s = 1.80 us ± 0.10 us"});
}

}  // namespace
}  // namespace fluxcal::report
