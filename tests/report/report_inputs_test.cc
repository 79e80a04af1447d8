// What the page takes from a recording set, a flux map and a diagnosis
// document (pipeline/report.h): the set's points, Udc and verdict, a map's
// nodes, the replay spectrum a document carries and what it does not.
#include "pipeline/report.h"

#include <gtest/gtest.h>

#include "fitting/fit.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {
namespace {

const std::string kBaldor = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol";

class ReportInputsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto set = io::ReadRecordingSet(kBaldor);
    ASSERT_TRUE(set.ok()) << set.status();
    set_ = new io::RecordingSet(std::move(*set));
    auto cal = fit::Fit(fit::FitDataFromRecording(*set_, {}));
    ASSERT_TRUE(cal.ok()) << cal.status();
    cal_ = new fit::Calibration(*cal);
    // No Udc: a page without the field-weakening table is built quickly.
    cal_->set_udc_v(std::nullopt);
  }
  static io::RecordingSet* set_;
  static fit::Calibration* cal_;
};
io::RecordingSet* ReportInputsTest::set_ = nullptr;
fit::Calibration* ReportInputsTest::cal_ = nullptr;

TEST_F(ReportInputsTest, RecordingSetGivesPointsUdcAndVerdict) {
  report::ReportInputs in;
  FillReportInputsFromJson(*cal_, cal_->ToJson(), &in);
  fit::FitData measured;
  ASSERT_TRUE(AddRecordingSetToReport(*set_, "baldor_eol", {}, &measured, &in).ok());
  EXPECT_EQ(in.identified, &measured);
  EXPECT_EQ(measured.inductances.size(), set_->hf_results.size()) << "hf_results rows (no waveforms to identify)";
  EXPECT_EQ(measured.steady_state.size(), set_->steady_state.size());
  ASSERT_TRUE(in.udc_v.has_value()) << "the manifest's, the calibration states none";
  EXPECT_EQ(*in.udc_v, 540.0);
  EXPECT_EQ(in.udc_source, "baldor_eol/manifest.json drive.udc_v");
  EXPECT_EQ(in.verdict, "pass");
  EXPECT_NE(in.verdict_basis.find("as the EOL flow does"), std::string::npos);
  // A Udc given by the caller stays.
  report::ReportInputs given;
  FillReportInputsFromJson(*cal_, cal_->ToJson(), &given);
  given.udc_v = 400.0;
  fit::FitData m2;
  ASSERT_TRUE(AddRecordingSetToReport(*set_, "baldor_eol", {}, &m2, &given).ok());
  EXPECT_EQ(*given.udc_v, 400.0);
}

TEST_F(ReportInputsTest, SetOfAnotherSerialIsRefusedNamingTheField) {
  io::RecordingSet other = *set_;
  other.manifest.serial = "OTHER-1";
  report::ReportInputs in;
  FillReportInputsFromJson(*cal_, cal_->ToJson(), &in);
  fit::FitData measured;
  const auto st = AddRecordingSetToReport(other, "other", {}, &measured, &in);
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("other/manifest.json: field 'serial'"), std::string::npos) << st;
}

TEST_F(ReportInputsTest, DiagnosisDocumentGivesItsSpectrumNotResidualMaps) {
  report::ReportInputs in;
  FillReportInputsFromJson(*cal_, cal_->ToJson(), &in);
  nlohmann::json doc = {{"format", "fluxcal.diagnosis.v1"},
                        {"serial", cal_->serial()},
                        {"verdict", "explained"},
                        {"waveform",
                         {{"residual_rms_before_a", 1.5},
                          {"residual_rms_after_a", 0.02},
                          {"spectrum_hz", {-100.0, 0.0, 100.0}},
                          {"spectrum_before_a", {0.5, 1.2, 0.4}},
                          {"spectrum_after_a", {0.01, 0.02, 0.01}}}}};
  AddDiagnosisDocumentToReport(doc, "diag.json", &in);
  ASSERT_EQ(in.diagnosis_figures.size(), 1u);
  EXPECT_NE(in.diagnosis_figures[0].svg.find("id=\"replay-spectrum\""), std::string::npos);
  EXPECT_NE(in.diagnosis_figures[0].caption.find("diag.json"), std::string::npos);
  EXPECT_NE(in.diagnosis_figures_note.find("Residual maps: not drawn"), std::string::npos);
  auto page = report::BuildReport(in);
  ASSERT_TRUE(page.ok()) << page.status();
  EXPECT_NE(page->html.find("id=\"replay-spectrum\""), std::string::npos);
  EXPECT_NE(page->html.find("--diagnose runs the diagnosis here"), std::string::npos);

  // Without a waveform block: no figure, and the page says so.
  doc.erase("waveform");
  AddDiagnosisDocumentToReport(doc, "diag.json", &in);
  EXPECT_TRUE(in.diagnosis_figures.empty());
  EXPECT_NE(in.diagnosis_figures_note.find("carries no replay spectrum"), std::string::npos);
}

}  // namespace
}  // namespace fluxcal::pipeline
