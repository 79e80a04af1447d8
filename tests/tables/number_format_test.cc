// The exporters' numbers (tables/export.cc: internal::Num, AppendNum) are
// the bytes printf's "%.17g" writes, on doubles of every kind: random bit
// patterns, log-uniform magnitudes of both signs, whole numbers, values
// with an exact tie at the 17th digit, neighbours of powers of ten (where
// rounding carries into the next decade), tiny, huge, subnormal, -0,
// infinities and NaN.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>

#include "gtest/gtest.h"
#include "tables/internal_formats.h"

namespace fluxcal::tables {
namespace {

std::string Printf17(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// Compares Num(v) with printf; counts mismatches and reports the first few.
struct Comparer {
  long checked = 0, mismatches = 0;
  void operator()(double v) {
    ++checked;
    const std::string want = Printf17(v), got = internal::Num(v);
    if (got != want && ++mismatches <= 10) ADD_FAILURE() << std::hexfloat << v << ": printf " << want << ", Num " << got;
    std::string appended = "x";
    internal::AppendNum(&appended, v);
    if (appended != "x" + want && ++mismatches <= 10) ADD_FAILURE() << std::hexfloat << v << ": AppendNum " << appended;
  }
};

double FromBits(uint64_t b) {
  double v;
  std::memcpy(&v, &b, 8);
  return v;
}

TEST(NumberFormat, AsPrintfSeventeenDigitsOnRandomDoubles) {
  Comparer cmp;
  std::mt19937_64 rng(20261126);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (int i = 0; i < 200000; ++i) {
    cmp(FromBits(rng()));                                                       // any bit pattern
    const double w = unit(rng) * std::pow(10.0, static_cast<int>(rng() % 44) - 22);   // magnitudes 1e-22 .. 1e21
    cmp(w);
    cmp(std::round(w * 1e6) / 1e6);                                             // few decimals
    cmp(std::nextafter(std::round(w * 1e3) / 1e3, 1e300));                      // just above a short decimal
    cmp(1.0 + static_cast<double>(rng() % 1000000) / (1 << 17));                // ties at the 17th digit
    cmp(-static_cast<double>(rng() % 100000) * std::ldexp(1.0, -static_cast<int>(rng() % 60)));   // short binary
  }
  EXPECT_EQ(cmp.mismatches, 0) << "of " << cmp.checked;
}

TEST(NumberFormat, AsPrintfSeventeenDigitsInEveryBinade) {
  // Every binary exponent from 2^-40 to 2^60, random and extreme mantissas.
  Comparer cmp;
  std::mt19937_64 rng(17);
  for (uint64_t be = 1023 - 40; be <= 1023 + 60; ++be) {
    for (uint64_t i = 0; i < 2000; ++i) {
      const uint64_t mant = i < 16 ? i : i < 32 ? ((uint64_t{1} << 52) - 1 - (i - 16)) : (rng() & ((uint64_t{1} << 52) - 1));
      cmp(FromBits((be << 52) | mant));
      cmp(FromBits((uint64_t{1} << 63) | (be << 52) | mant));
    }
  }
  EXPECT_EQ(cmp.mismatches, 0) << "of " << cmp.checked;
}

TEST(NumberFormat, AsPrintfSeventeenDigitsAtTheEdges) {
  Comparer cmp;
  // Neighbours of the powers of ten, where the 17 digits round into the
  // next decade or the layout switches between fixed and scientific.
  for (int k = -12; k <= 18; ++k) {
    const double p = std::pow(10.0, k);
    double below = p, above = p;
    for (int j = 0; j < 100; ++j) {
      below = std::nextafter(below, 0.0);
      above = std::nextafter(above, 1e300);
      cmp(below);
      cmp(above);
      cmp(-below);
    }
    cmp(p);
  }
  for (double v : {0.0, -0.0, 1.0, -1.0, 0.1, 0.5, 1e15, 1e15 + 0.5, 1e16, 1e17, 123456789012345678.0, 1e-5, 1e-4,
                   9.5367431640625e-07, std::numeric_limits<double>::min(), std::numeric_limits<double>::denorm_min(),
                   std::numeric_limits<double>::max(), std::numeric_limits<double>::lowest(),
                   std::numeric_limits<double>::epsilon(), std::numeric_limits<double>::infinity(),
                   -std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()}) {
    cmp(v);
  }
  EXPECT_EQ(cmp.mismatches, 0) << "of " << cmp.checked;
}

}  // namespace
}  // namespace fluxcal::tables
