// The report page against its sources: the table checksums it prints are
// the tables library's for the same limits, the limits say where they came
// from, a bad diagnosis document is refused naming file and field, and text
// from the inputs is escaped. Fixture: the public Baldor EOL set (real
// machine, hf_results; data/real/baldor_eol), fitted here.
#include "report/report.h"

#include <gtest/gtest.h>

#include "absl/strings/str_format.h"
#include "fitting/fit.h"
#include "io/recording_set.h"
#include "tables/tables.h"

namespace fluxcal::report {
namespace {

size_t Count(const std::string& s, const std::string& what) {
  size_t n = 0;
  for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
  return n;
}

class ReportTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const std::string dir = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol";
    auto set = io::ReadRecordingSet(dir);
    ASSERT_TRUE(set.ok()) << set.status();
    data_ = new fit::FitData(fit::FitDataFromHfRows(&set->manifest, set->hf_results));
    auto cal = fit::Fit(*data_);
    ASSERT_TRUE(cal.ok()) << cal.status();
    cal_ = new fit::Calibration(*cal);
  }
  ReportInputs Inputs() const {
    ReportInputs in;
    in.calibration = cal_;
    in.calibration_json = cal_->ToJson();
    in.calibration_path = "baldor.json";
    in.software_version = "test";
    return in;
  }
  static fit::FitData* data_;
  static fit::Calibration* cal_;
};
fit::FitData* ReportTest::data_ = nullptr;
fit::Calibration* ReportTest::cal_ = nullptr;

TEST_F(ReportTest, ChecksumsAreTheTablesLibrarys) {
  ReportInputs in = Inputs();
  in.udc_v = 540.0;
  in.udc_source = "test: 540 V";
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_EQ(rep->figures, 8);
  EXPECT_EQ(Count(rep->html, "<svg "), 8u);
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
  EXPECT_NE(rep->html.find("class=\"warn\""), std::string::npos);
  EXPECT_NE(rep->html.find("below the resistive drop"), std::string::npos);
  EXPECT_NE(rep->html.find("test: 50 V"), std::string::npos);
}

// Without --udc-v or a set, Udc is the calibration's (the Baldor set's
// manifest says 540 V); never a default of some other drive.
TEST_F(ReportTest, UdcFromTheCalibration) {
  ASSERT_TRUE(cal_->udc_v().has_value());
  EXPECT_EQ(*cal_->udc_v(), 540.0);
  auto rep = BuildReport(Inputs());
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_EQ(rep->figures, 8);
  EXPECT_NE(rep->html.find("540 V <small>(the calibration"), std::string::npos) << "Udc and its source on the page";
  EXPECT_EQ(rep->html.find("class=\"warn\""), std::string::npos) << "540 V fits this machine";
  EXPECT_GT(rep->ellipse_speed_rpm, 0.0);
}

// Udc known nowhere: the page says the voltage limit and field weakening
// cannot be drawn instead of drawing them at an assumed voltage (before,
// 50 V: a map clamped everywhere on a page that said pass). MTPA and MTPV
// need no Udc and are still there, checksums as the tables library's.
TEST_F(ReportTest, UnknownUdcDrawsNoVoltageLimit) {
  fit::Calibration cal = *cal_;
  cal.set_udc_v(std::nullopt);
  ReportInputs in = Inputs();
  in.calibration = &cal;
  in.calibration_json = cal.ToJson();
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_NE(rep->html.find("The voltage limit and the field-weakening map cannot be drawn"), std::string::npos);
  EXPECT_NE(rep->html.find("the DC-link voltage Udc is not known"), std::string::npos);
  EXPECT_EQ(rep->html.find("id=\"fig-fw-"), std::string::npos) << "no field-weakening figure without Udc";
  EXPECT_EQ(rep->figures, 6) << "five surfaces and the current plane";
  EXPECT_EQ(rep->ellipse_speed_rpm, 0.0);
  EXPECT_EQ(rep->html.find("|u| ="), std::string::npos) << "no voltage-limit curve";
  EXPECT_NE(rep->html.find("<tr><td>fw</td><td colspan=\"6\">not computed"), std::string::npos);
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
  ReportInputs in = Inputs();
  in.identified = data_;
  auto rep = BuildReport(in);
  ASSERT_TRUE(rep.ok()) << rep.status();
  // Ldd, Lqq and Ldq each draw every identified point that has the value
  // (six id levels: all of them have a curve), plus one legend dot.
  auto figure = [&](const std::string& id) {
    const size_t a = rep->html.find("id=\"" + id + "\"");
    return a == std::string::npos ? std::string() : rep->html.substr(a, rep->html.find("</svg>", a) - a);
  };
  size_t with_ldq = 0;
  for (const auto& o : data_->inductances) with_ldq += o.ldq_h.has_value();
  EXPECT_EQ(Count(figure("fig-ldd"), "<circle "), data_->inductances.size() + 1);
  EXPECT_EQ(Count(figure("fig-lqq"), "<circle "), data_->inductances.size() + 1);
  EXPECT_EQ(Count(figure("fig-ldq"), "<circle "), with_ldq + (with_ldq > 0 ? 1 : 0));
}

TEST_F(ReportTest, DiagnosisOfTheWrongFormatNamesFileAndField) {
  ReportInputs in = Inputs();
  in.diagnosis = nlohmann::json{{"format", "something.else"}};
  in.diagnosis_path = "diag.json";
  auto rep = BuildReport(in);
  ASSERT_FALSE(rep.ok());
  EXPECT_EQ(rep.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(rep.status().message().find("diag.json: field 'format'"), std::string::npos) << rep.status();
}

TEST_F(ReportTest, DiagnosisTextIsEscaped) {
  ReportInputs in = Inputs();
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
  EXPECT_NE(rep->html.find("&lt;script&gt;"), std::string::npos);
  EXPECT_NE(rep->html.find("dead_time_s = 1.8e-06 +- 1e-07"), std::string::npos);
}

}  // namespace
}  // namespace fluxcal::report
