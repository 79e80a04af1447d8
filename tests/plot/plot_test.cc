// The figure API's pieces against exact answers: 1-2-5 ticks, tick labels,
// marching squares on a field whose level sets are known circles, and the
// SVG's promises (a legend entry per labelled mark, unique clip ids, the
// colour bar's intermediate ticks).
#include "plot/plot.h"

#include <cmath>
#include <regex>

#include <gtest/gtest.h>

namespace fluxcal::plot {
namespace {

TEST(NiceTicks, OneTwoFiveStepsCoverTheRange) {
  EXPECT_EQ(NiceTicks(0, 100, 5), (std::vector<double>{0, 20, 40, 60, 80, 100}));
  EXPECT_EQ(NiceTicks(-97.3, 3.1, 5), (std::vector<double>{-100, -50, 0, 50}));
  EXPECT_EQ(NiceTicks(-97.3, 3.1, 7), (std::vector<double>{-100, -80, -60, -40, -20, 0, 20}));
  const auto t = NiceTicks(0.00123, 0.00871, 6);
  ASSERT_GE(t.size(), 2u);
  const double step = t[1] - t[0];
  EXPECT_NEAR(step, 0.002, 1e-15) << "expected a 2e-3 step (6 ticks) for a 7.5e-3 wide range, got " << step;
  EXPECT_LE(t.front(), 0.00123);
  EXPECT_GE(t.back(), 0.00871);
  for (double lo : {-3.7, 0.0, 12.0, 1e-6}) {
    for (double width : {0.013, 1.0, 7.0, 480.0}) {
      const auto v = NiceTicks(lo, lo + width, 5);
      const double s = v[1] - v[0];
      const double mant = s / std::pow(10.0, std::floor(std::log10(s) + 1e-12));
      EXPECT_TRUE(std::abs(mant - 1) < 1e-9 || std::abs(mant - 2) < 1e-9 || std::abs(mant - 5) < 1e-9)
          << "step " << s << " for [" << lo << ", " << lo + width << "]";
      EXPECT_LE(v.front(), lo);
      EXPECT_GE(v.back(), lo + width);
      EXPECT_GE(v.size(), 3u);
      EXPECT_LE(v.size(), 9u);
    }
  }
}

TEST(NiceTicks, DegenerateRangeIsWidened) {
  const auto t = NiceTicks(5, 5);
  EXPECT_LT(t.front(), 5);
  EXPECT_GT(t.back(), 5);
}

TEST(FormatTick, DigitsFollowTheStep) {
  EXPECT_EQ(FormatTick(0.05, 0.05), "0.05");
  EXPECT_EQ(FormatTick(120, 20), "120");
  EXPECT_EQ(FormatTick(-0.5, 0.5), "-0.5");
  EXPECT_EQ(FormatTick(0, 0.1), "0");
}

TEST(ContourLines, CircleOfKnownRadius) {
  // z = x^2 + y^2 on a 61 x 61 grid over [-2, 2]^2; level 1 is the unit
  // circle. Linear interpolation on a 0.067 grid is good to 1e-2.
  std::vector<double> xs, ys, z;
  for (int k = 0; k <= 60; ++k) xs.push_back(-2 + 4.0 * k / 60);
  ys = xs;
  for (double y : ys) for (double x : xs) z.push_back(x * x + y * y);
  const auto lines = ContourLines(xs, ys, z, 1.0);
  ASSERT_EQ(lines.size(), 1u) << "the unit circle should come out as one joined polyline";
  EXPECT_GT(lines[0].size(), 100u);
  for (const auto& [x, y] : lines[0]) EXPECT_NEAR(std::hypot(x, y), 1.0, 1e-2) << "at (" << x << ", " << y << ")";
  EXPECT_EQ(lines[0].front(), lines[0].back()) << "a closed level set should close";
}

TEST(ContourLines, NanCellsAreSkipped) {
  std::vector<double> xs{0, 1, 2}, ys{0, 1};
  std::vector<double> z{0, 1, std::nan(""), 0, 1, std::nan("")};
  const auto lines = ContourLines(xs, ys, z, 0.5);
  ASSERT_EQ(lines.size(), 1u);
  for (const auto& p : lines[0]) EXPECT_NEAR(p.first, 0.5, 1e-12);
}

TEST(Figure, LegendEntryPerLabelledMarkAndUniqueIds) {
  Figure f("fig-a", 600, 400);
  f.SetXLabel("id [A]");
  f.SetYLabel("iq [A]");
  f.Line({0, 1, 2}, {0, 1, 4}, Style{}, "parabola");
  f.Scatter({0.5, 1.5}, {0.3, 2.1}, Style{}, "points", {0.1, 0.2});
  f.Line({0, 2}, {1, 1}, Style{}, "");   // unlabelled: no entry
  EXPECT_EQ(f.LegendEntries(), 2u);
  const std::string svg = f.Svg();
  EXPECT_NE(svg.find("id=\"fig-a-clip\""), std::string::npos);
  EXPECT_NE(svg.find(">parabola<"), std::string::npos);
  EXPECT_NE(svg.find(">points<"), std::string::npos);
  EXPECT_NE(svg.find(">id [A]<"), std::string::npos);
  EXPECT_NE(svg.find("width=\"600.0\" height=\"400.0\""), std::string::npos);
}

TEST(Figure, HeatmapColourBarHasIntermediateTicks) {
  Figure f("fig-h", 600, 400);
  std::vector<double> xs{0, 1, 2, 3}, ys{0, 10, 20}, z;
  for (double y : ys) for (double x : xs) z.push_back(x + y);
  f.Heatmap(xs, ys, z, "sum [1]");
  const std::string svg = f.Svg();
  // 0 .. 23 gives ticks 0, 5, ..., 25: at least four labelled values on
  // the bar besides the ends.
  int labels = 0;
  for (const char* v : {">5<", ">10<", ">15<", ">20<"}) labels += svg.find(v) != std::string::npos;
  EXPECT_EQ(labels, 4) << svg.substr(0, 400);
  EXPECT_NE(svg.find(">sum [1]<"), std::string::npos);
}

TEST(ColourMap, EndsAndClamp) {
  EXPECT_EQ(ColourMap(0), "#440154");
  EXPECT_EQ(ColourMap(1), "#fde725");
  EXPECT_EQ(ColourMap(7), "#fde725");
}

}  // namespace
}  // namespace fluxcal::plot
