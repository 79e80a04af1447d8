// The page's numbers: each rounded to what it means, never "-0", no
// sixteen digits of a double (report/format.h).
#include "report/format.h"

#include <gtest/gtest.h>

#include <cmath>

namespace fluxcal::report {
namespace {

TEST(Format, QuantitiesRoundToTheirMeaning) {
  EXPECT_EQ(Num(0.02556, kCurrentA), "0.03");
  EXPECT_EQ(Num(-18.0, kCurrentA), "-18");
  EXPECT_EQ(Num(0.16, kCurrentA, "A"), "0.16 A");
  EXPECT_EQ(Num(17.98764, kCurrentA), "18");
  EXPECT_EQ(Num(311.769, kVoltageV, "V"), "312 V");
  EXPECT_EQ(Num(1181.63, kSpeedRpm, "rpm"), "1182 rpm");
  EXPECT_EQ(Num(0.446782133, kFluxWb, "Wb"), "0.4468 Wb");
  EXPECT_EQ(Num(3.6, kResistanceOhm), "3.6");
  EXPECT_EQ(Num(0.0112, kResistanceOhm), "0.0112");
  EXPECT_EQ(Num(2582445.38, kStatistic), "2582445");
  EXPECT_EQ(Num(42481.15, kStatistic), "42481.2");
  EXPECT_EQ(Num(100 * 0.00063, kPercent, "%"), "0.063 %");
}

TEST(Format, NoMinusZero) {
  EXPECT_EQ(Num(-0.0, kCurrentA), "0");
  EXPECT_EQ(Num(-0.004, kCurrentA), "0");        // below the resolution
  EXPECT_EQ(Num(-1e-17, Rounding{4, 0}), "-1e-17");   // no resolution: the value as it is
  EXPECT_EQ(Range(-18, -0.0, kCurrentA, "A"), "-18 .. 0 A");
  EXPECT_EQ(RoundNumbersInText("iq = -0 A"), "iq = 0 A");
}

TEST(Format, ExtremesAndNonFinite) {
  EXPECT_EQ(Num(3.2e-9, Rounding{2, 0}), "3.2e-09");
  EXPECT_EQ(Num(2.5e8, Rounding{3, 0}), "2.5e+08");
  EXPECT_EQ(Num(1234567, Rounding{3, 0}), "1230000");
  EXPECT_EQ(Num(std::nan(""), kCurrentA), "n/a");
}

TEST(Format, ValueRoundedToItsDeviation) {
  EXPECT_EQ(ValueWithStd("dead_time_s", 2.50762e-06, 1.349e-09), "2.5076 us ± 0.0013 us");
  EXPECT_EQ(ValueWithStd("dead_time_s", 1.8e-6, 1e-7), "1.80 us ± 0.10 us");
  EXPECT_EQ(ValueWithStd("rs_ohm", 0.0123456, 0.00042), "12.35 mohm ± 0.42 mohm");
  EXPECT_EQ(ValueWithStd("psi_pm_wb", 0.446782, 0), "446.8 mWb");
  EXPECT_EQ(ValueWithStd("gain", 1.0312345, 0.0021), "1.0312 ± 0.0021");
  EXPECT_EQ(ValueWithStd("offset_b_a", 1234.6, 56.7), "1.235 kA ± 0.057 kA");
}

TEST(Format, NumbersInFreeText) {
  // Units round as their quantity; a bare number to four digits; words,
  // identifiers, versions and integers are left alone.
  EXPECT_EQ(RoundNumbersInText("hf point (id -39.58 A, iq 0.04947 A): lqq_h off by -4.7 % (16 sigma)"),
            "hf point (id -39.6 A, iq 0.05 A): lqq_h off by -4.7 % (16 sigma)");
  EXPECT_EQ(RoundNumbersInText("cv=341.61234 bic=2.992e+04"), "cv=341.6 bic=29920");
  EXPECT_EQ(RoundNumbersInText("p003 steady_state[7] fluxcal 0.1.0 e70b4b5baaf4"),
            "p003 steady_state[7] fluxcal 0.1.0 e70b4b5baaf4");
  EXPECT_EQ(RoundNumbersInText("a 0.0005595 H drift"), "a 0.0005595 H drift");
  EXPECT_EQ(RoundNumbersInText("0.00055951 H"), "0.0005595 H");
}

}  // namespace
}  // namespace fluxcal::report
