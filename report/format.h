// Numbers on the report page, each rounded to what it means: a current to
// three significant digits but never finer than 10 mA, a checksum's table
// axis as the breakpoint it is, a value with a standard deviation to the
// deviation's two digits. One helper for every number the page prints (its
// tables, captions, legends and titles), so that no "0.02556 A" or "-0 A"
// reaches a reader. Tick labels are the plot module's (plot::FormatTick).
#ifndef FLUXCAL_REPORT_FORMAT_H_
#define FLUXCAL_REPORT_FORMAT_H_

#include <string>

namespace fluxcal::report {

// Significant digits, and the finest step worth printing in the unit shown
// (0: none). The value is rounded to the step first, then to the digits.
struct Rounding {
  int digits = 4;
  double resolution = 0;
};

// Per quantity, in the unit the page shows it in. The resolutions are what
// a bench or an ECU table can tell apart: 10 mA of current, 1 uH, 0.1 mWb
// of flux, 0.1 V, 1 rpm, 10 mN m, 0.1 mohm.
inline constexpr Rounding kCurrentA{3, 0.01};
inline constexpr Rounding kInductanceMh{3, 0.001};
inline constexpr Rounding kInductanceUh{3, 1};
inline constexpr Rounding kFluxWb{4, 1e-4};
inline constexpr Rounding kFluxMwb{4, 0.1};
inline constexpr Rounding kVoltageV{3, 0.1};
inline constexpr Rounding kSpeedRpm{4, 1};
inline constexpr Rounding kTorqueNm{3, 0.01};
inline constexpr Rounding kPowerKw{3, 0.01};
inline constexpr Rounding kResistanceOhm{3, 1e-4};
inline constexpr Rounding kPercent{2, 0.001};
inline constexpr Rounding kSigma{3, 0.1};      // significance in standard deviations
inline constexpr Rounding kZ{2, 0.01};         // a z score
inline constexpr Rounding kStatistic{7, 0.1};  // chi2, BIC: differences of a few units matter
inline constexpr Rounding kRatio{3, 0};        // a dimensionless ratio (modulation limit, ...)
inline constexpr Rounding kTemperatureC{3, 0.1};

// The number as text: fixed notation from 1e-4 to 1e7 (beyond, "3.2e-06"),
// trailing zeros of the fraction dropped, never "-0"; "n/a" for NaN.
std::string Num(double v, Rounding r);
// The number and its unit: "18 A", "0.16 A", "312 V".
std::string Num(double v, Rounding r, const std::string& unit);
// "a .. b unit", both ends rounded alike.
std::string Range(double lo, double hi, Rounding r, const std::string& unit);

// A value with its standard deviation, both in the SI unit that the
// name's suffix states (dead_time_s, rs_ohm, ld_h, psi_pm_wb, ...), scaled
// to an engineering prefix and rounded to the deviation's two significant
// digits: "2.5080 us +- 0.0013 us". Without a deviation (sd <= 0 or NaN)
// four significant digits. A name without a known suffix: no unit.
std::string ValueWithStd(const std::string& name, double value, double sd);

// Free text another library wrote (a fit's model-selection line, a reason
// a point was left out, a diagnosis' explanation): every decimal number in
// it with more than `digits` significant digits rounded to `digits`, and
// "-0" written "0". Integers and words are left alone.
std::string RoundNumbersInText(const std::string& text, int digits = 4);

}  // namespace fluxcal::report

#endif  // FLUXCAL_REPORT_FORMAT_H_
