// The physical plausibility limits shared by the service and the flux-map
// reader: each bound is where io/plausibility.h says, the message names the
// field, the rule and the value, and a non-finite value is refused.
#include "io/plausibility.h"

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "gtest/gtest.h"

namespace fluxcal::io {
namespace {

using Check = std::function<absl::Status(std::string_view, double)>;

void ExpectRange(const char* name, const Check& check, double lo, double hi, bool hi_open, const std::string& rule) {
  EXPECT_TRUE(check("f", lo).ok()) << name << " at its lower bound " << lo;
  EXPECT_EQ(check("f", hi).ok(), !hi_open) << name << " at its upper bound " << hi;
  EXPECT_TRUE(check("f", std::nextafter(hi, lo)).ok()) << name << " just below " << hi;
  const double below = std::nextafter(lo, -std::numeric_limits<double>::infinity());
  const double above = std::nextafter(hi, std::numeric_limits<double>::infinity());
  for (double bad : {below, above}) {
    const auto s = check("points[3].x", bad);
    ASSERT_FALSE(s.ok()) << name << " accepted " << bad;
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(std::string(s.message()).rfind("points[3].x: " + rule + ", got ", 0), 0u) << s.message();
  }
  const auto nan = check("f", std::nan(""));
  ASSERT_FALSE(nan.ok()) << name << " accepted NaN";
  EXPECT_NE(std::string(nan.message()).find("must be a finite number"), std::string::npos) << nan.message();
  EXPECT_FALSE(check("f", std::numeric_limits<double>::infinity()).ok()) << name << " accepted infinity";
}

TEST(Plausibility, LimitsAndMessages) {
  ExpectRange("current", CheckCurrentA, -1e4, 1e4, false, "must be within +-10 kA");
  ExpectRange("speed", CheckSpeedRpm, -1e5, 1e5, false, "must be within +-100000 rpm");
  ExpectRange("psi_pm", CheckPsiPmWb, 0, 10, false, "must be 0..10 Wb");
  ExpectRange("rs", CheckRsOhm, 0, 10, false, "must be 0..10 Ohm");
  ExpectRange("temperature", CheckTemperatureC, -60, 250, false, "must be -60..250 degC");
  ExpectRange("ldq", CheckCrossInductanceH, -1, 1, false, "must be within +-1 H");
  ExpectRange("l std", CheckInductanceStdH, 0, 1, false, "must be 0..1 H");
  // Inductance: [1e-7, 1) H, the message the service has always sent.
  EXPECT_TRUE(CheckInductanceH("f", 1e-7).ok());
  EXPECT_TRUE(CheckInductanceH("f", std::nextafter(1.0, 0.0)).ok());
  EXPECT_FALSE(CheckInductanceH("f", 1.0).ok()) << "1 H is out (half-open)";
  EXPECT_FALSE(CheckInductanceH("f", std::nan("")).ok());
  EXPECT_EQ(std::string(CheckInductanceH("points[3].ld_h", -1e-4).message()),
            "points[3].ld_h: must be in [1e-7, 1) H, got -0.0001");
  EXPECT_TRUE(CheckPolePairs("p", 1).ok());
  EXPECT_TRUE(CheckPolePairs("p", 100).ok());
  EXPECT_EQ(std::string(CheckPolePairs("motor.pole_pairs", 0).message()), "motor.pole_pairs: must be 1..100, got 0");
  EXPECT_FALSE(CheckPolePairs("p", 101).ok());
}

}  // namespace
}  // namespace fluxcal::io
