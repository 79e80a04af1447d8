// The figure API's pieces against exact answers: 1-2-5 ticks, tick labels,
// marching squares on a field whose level sets are known circles, and the
// SVG's promises, read back from the SVG through an XML parser: a legend
// entry per labelled mark, unique clip ids, round tick labels on the axes
// and along the colour bar, every text inside its figure, bars cut at a log
// axis's floor, marker shapes that differ from data dots.
#include "plot/plot.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <regex>
#include <set>
#include <string>

#include <gtest/gtest.h>
#include <tinyxml2.h>

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

// ---------------------------------------------------------------- SVG reading

using tinyxml2::XMLElement;

// Every element below `e` (depth first), not descending into nested <svg>s
// (a panel has its own coordinates).
void Walk(const XMLElement* e, const std::function<void(const XMLElement*)>& f) {
  for (const XMLElement* c = e->FirstChildElement(); c; c = c->NextSiblingElement()) {
    f(c);
    if (std::strcmp(c->Name(), "svg") != 0) Walk(c, f);
  }
}

const XMLElement* Group(const XMLElement* svg, const char* cls) {
  const XMLElement* found = nullptr;
  Walk(svg, [&](const XMLElement* e) {
    const char* c = e->Attribute("class");
    if (!found && std::strcmp(e->Name(), "g") == 0 && c && std::strcmp(c, cls) == 0) found = e;
  });
  return found;
}

std::vector<std::string> Texts(const XMLElement* g) {
  std::vector<std::string> out;
  if (g == nullptr) return out;
  Walk(g, [&](const XMLElement* e) {
    if (std::strcmp(e->Name(), "text") == 0 && e->GetText()) out.push_back(e->GetText());
  });
  return out;
}

size_t CountClass(const XMLElement* svg, const char* cls) {
  size_t n = 0;
  Walk(svg, [&](const XMLElement* e) {
    const char* c = e->Attribute("class");
    n += c && std::strcmp(c, cls) == 0;
  });
  return n;
}

// Texts that run past the figure's width or height, at the glyph width the
// layout assumes (0.62 font size per character; the report's page check
// uses the same); rotated labels (-90 degrees about their anchor) checked
// along their length. Nested panels are checked in their own coordinates
// and against their parent's size.
std::vector<std::string> OutsideViewBox(const XMLElement* svg) {
  std::vector<std::string> bad;
  const double w = svg->DoubleAttribute("width"), h = svg->DoubleAttribute("height");
  Walk(svg, [&](const XMLElement* e) {
    if (std::strcmp(e->Name(), "svg") == 0) {
      const double x = e->DoubleAttribute("x"), y = e->DoubleAttribute("y");
      if (x < 0 || y < 0 || x + e->DoubleAttribute("width") > w + 0.5 || y + e->DoubleAttribute("height") > h + 0.5) {
        bad.push_back(std::string("panel ") + e->Attribute("id"));
      }
      for (auto& b : OutsideViewBox(e)) bad.push_back(b);
      return;
    }
    if (std::strcmp(e->Name(), "text") != 0 || !e->GetText()) return;
    const std::string t = e->GetText();
    const double fs = e->DoubleAttribute("font-size", 11), tw = 0.62 * fs * t.size();
    const double x = e->DoubleAttribute("x"), y = e->DoubleAttribute("y");
    const char* anchor = e->Attribute("text-anchor");
    const double shift = anchor == nullptr                     ? 0
                         : std::strcmp(anchor, "middle") == 0 ? tw / 2
                         : std::strcmp(anchor, "end") == 0    ? tw
                                                              : 0;
    bool out;
    if (e->Attribute("transform")) {   // rotate(-90 x y): the text runs upwards from y + shift
      out = x - fs < -0.5 || x > w + 0.5 || y + shift > h + 0.5 || y + shift - tw < -0.5;
    } else {
      out = x - shift < -0.5 || x - shift + tw > w + 0.5 || y - fs < -0.5 || y > h + 0.5;
    }
    if (out) bad.push_back(t + " at (" + std::to_string(x) + ", " + std::to_string(y) + ")");
  });
  return bad;
}

// A label is a round tick when it is an integer multiple of a step of 1, 2
// or 5 times a power of ten and consecutive labels differ by that step.
void ExpectRoundTicks(const std::vector<std::string>& labels, const std::string& what) {
  ASSERT_GE(labels.size(), 3u) << what << ": too few ticks";
  std::vector<double> v;
  for (const auto& l : labels) v.push_back(std::stod(l));
  const double step = v[1] - v[0];
  const double mant = std::abs(step) / std::pow(10.0, std::floor(std::log10(std::abs(step)) + 1e-9));
  EXPECT_TRUE(std::abs(mant - 1) < 1e-6 || std::abs(mant - 2) < 1e-6 || std::abs(mant - 5) < 1e-6)
      << what << ": step " << step;
  for (size_t k = 0; k < v.size(); ++k) {
    EXPECT_NEAR(v[k] / step, std::round(v[k] / step), 1e-6) << what << ": " << labels[k] << " is not on the step";
    if (k > 0) {
      EXPECT_NEAR(v[k] - v[k - 1], step, 1e-9 * std::max(1.0, std::abs(step))) << what;
    }
  }
}

struct Parsed {
  tinyxml2::XMLDocument doc;
  const XMLElement* svg = nullptr;
  explicit Parsed(const std::string& text) {
    EXPECT_EQ(doc.Parse(text.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
    svg = doc.RootElement();
  }
};

TEST(FormatDecade, PlainInTheMiddleExponentOutside) {
  EXPECT_EQ(FormatDecade(0), "1");
  EXPECT_EQ(FormatDecade(-2), "0.01");
  EXPECT_EQ(FormatDecade(-3), "0.001");
  EXPECT_EQ(FormatDecade(3), "1000");
  EXPECT_EQ(FormatDecade(-5), "1e-05");
  EXPECT_EQ(FormatDecade(6), "1e+06");
}

TEST(Figure, OddDataRangesGetRoundTickLabels) {
  // The old hand-written plots labelled quarters of the data range
  // (-100, -73, -45 ...; 0.165, 0.169 ...). The axes label 1-2-5 steps.
  Figure f("fig-r", 640, 420);
  f.SetXLabel("id [A]");
  f.SetYLabel("Ldd [mH]");
  f.Line({-109.7, -53.1, 3.3}, {0.1652, 0.1671, 0.1693}, Style{}, "curve");
  Parsed p(f.Svg());
  ExpectRoundTicks(Texts(Group(p.svg, "xticks")), "x axis");
  ExpectRoundTicks(Texts(Group(p.svg, "yticks")), "y axis");
  // The frame starts and ends on a labelled tick: the data lie inside.
  const auto xs = Texts(Group(p.svg, "xticks"));
  EXPECT_LE(std::stod(xs.front()), -109.7);
  EXPECT_GE(std::stod(xs.back()), 3.3);
}

TEST(Figure, ColourBarHasRoundTicksAlongItsLength) {
  // A narrow range (0.165 .. 0.169) whose ends are not round.
  Figure f("fig-cb", 640, 420);
  std::vector<double> xs{0, 1, 2, 3}, ys{0, 1, 2}, z;
  for (double y : ys) for (double x : xs) z.push_back(0.1652 + 0.0006 * x + 0.0011 * y);
  f.Heatmap(xs, ys, z, "L [mH]");
  Parsed p(f.Svg());
  const auto bar = Texts(Group(p.svg, "colourbar"));
  ASSERT_FALSE(bar.empty());
  EXPECT_EQ(bar.back(), "L [mH]") << "the bar's title is its last text";
  const std::vector<std::string> ticks(bar.begin(), bar.end() - 1);
  EXPECT_GE(ticks.size(), 4u) << "labels along the bar, not only its ends";
  ExpectRoundTicks(ticks, "colour bar");
  EXPECT_TRUE(OutsideViewBox(p.svg).empty());
}

TEST(Figure, EverySeriesHasALegendEntryWithItsMark) {
  Figure f("fig-l", 700, 420);
  Style line, dots, bars, cross, square, contour;
  dots.colour = "#d62728";
  bars.colour = "#2ca02c";
  cross.marker = Marker::kCross;
  square.marker = Marker::kSquare;
  contour.colour = "#777";
  std::vector<double> gx{0, 1, 2}, gy{0, 1, 2}, gz{0, 1, 2, 1, 2, 3, 2, 3, 4};
  f.Line({0, 1, 2}, {0, 1, 4}, line, "parabola");
  f.Scatter({0.5, 1.5}, {0.3, 2.1}, dots, "points", {0.1, 0.2});
  f.Bars({0, 1, 2}, {1, 2, 3}, 0.3, bars, "counts");
  f.Scatter({1}, {1}, cross, "clamped");
  f.Scatter({2}, {2}, square, "extrapolated");
  f.Contours(gx, gy, gz, {1, 2}, contour, "level");
  f.Line({0, 2}, {1, 1}, Style{}, "");   // unlabelled: no entry
  f.Note("a note without a mark");
  EXPECT_EQ(f.LegendEntries(), 7u);
  Parsed p(f.Svg());
  const XMLElement* legend = Group(p.svg, "legend");
  ASSERT_NE(legend, nullptr);
  const auto labels = Texts(legend);
  EXPECT_EQ(labels, (std::vector<std::string>{"parabola", "points", "counts", "clamped", "extrapolated", "level",
                                               "a note without a mark"}));
  // Each series' key is drawn in its own kind: a line, a dot, a swatch, a
  // cross (path), a square (rect), a line; the note has none.
  std::vector<std::string> keys;
  for (const XMLElement* e = legend->FirstChildElement(); e; e = e->NextSiblingElement()) {
    const char* c = e->Attribute("class");
    if (std::strcmp(e->Name(), "text") == 0 || (c && std::strcmp(c, "halo") == 0)) continue;
    keys.push_back(e->Name());
  }
  EXPECT_EQ(keys, (std::vector<std::string>{"line", "circle", "rect", "path", "rect", "line"}));
  EXPECT_TRUE(OutsideViewBox(p.svg).empty());
}

TEST(Figure, MarkerShapesDifferFromDataDots) {
  Figure f("fig-m", 500, 300);
  Style dot, cross, square;
  cross.marker = Marker::kCross;
  square.marker = Marker::kSquare;
  f.Scatter({0, 1, 2}, {0, 1, 2}, dot, "valid");
  f.Scatter({0.5}, {0.5}, cross, "clamped");
  f.Scatter({1.5, 1.7}, {1.5, 1.2}, square, "extrapolated");
  Parsed p(f.Svg());
  std::map<std::string, size_t> kinds;
  Walk(p.svg, [&](const XMLElement* e) {
    const char* c = e->Attribute("class");
    if (c && std::strcmp(c, "point") == 0) ++kinds[e->Name()];
  });
  EXPECT_EQ(kinds["circle"], 3u);
  EXPECT_EQ(kinds["path"], 1u) << "the cross";
  EXPECT_EQ(kinds["rect"], 2u) << "the squares";
  // Open shapes get a halo so they show on dark and light cells alike.
  EXPECT_EQ(CountClass(p.svg, "halo"), 3u + 2u) << "three in the plot, two in the legend";
}

TEST(Figure, TextStaysInsideTheViewBox) {
  // A long title, a long y label, wide tick labels and more legend entries
  // than one column holds: all wrapped or laid out inside the figure.
  Figure f("fig-t", 480, 260);
  f.SetTitle("A title that is far too long for a figure this narrow and must be wrapped onto more lines");
  f.SetXLabel("frequency [Hz]");
  f.SetYLabel("amplitude [A]");
  for (int k = 0; k < 14; ++k) {
    Style st;
    st.colour = Palette(k);
    f.Line({-2500, 2500}, {1e5 + k, 2e5 + k}, st, "series number " + std::to_string(k));
  }
  EXPECT_EQ(f.LegendEntries(), 14u);
  Parsed p(f.Svg());
  const auto bad = OutsideViewBox(p.svg);
  EXPECT_TRUE(bad.empty()) << bad.size() << " outside, first: " << (bad.empty() ? "" : bad[0]);
  EXPECT_EQ(Texts(Group(p.svg, "legend")).size(), 14u);
}

TEST(Figure, LegendBelowTheAxesWrapsIntoRowsInsideTheFigure) {
  Figure f("fig-lb", 520, 420);
  f.SetXLabel("id [A]");
  f.SetLegendBelow(true);
  for (int k = 0; k < 7; ++k) {
    Style st;
    st.colour = Palette(k);
    f.Line({0, 1}, {1.0 * k, k + 1.0}, st, "a fairly long legend label " + std::to_string(k));
  }
  Parsed p(f.Svg());
  const XMLElement* clip = p.svg->FirstChildElement("defs")->FirstChildElement("clipPath")->FirstChildElement("rect");
  const double frame_bottom = clip->DoubleAttribute("y") + clip->DoubleAttribute("height");
  const double frame_right = clip->DoubleAttribute("x") + clip->DoubleAttribute("width");
  EXPECT_GT(frame_right, 520 - 30) << "no legend column takes the width";
  std::set<double> rows;
  Walk(Group(p.svg, "legend"), [&](const XMLElement* e) {
    if (std::strcmp(e->Name(), "text") != 0) return;
    EXPECT_GT(e->DoubleAttribute("y"), frame_bottom + 30) << "below the x axis and its label";
    rows.insert(e->DoubleAttribute("y"));
  });
  EXPECT_GE(rows.size(), 3u) << "seven long entries wrap into rows";
  EXPECT_TRUE(OutsideViewBox(p.svg).empty());
}

TEST(Figure, LogBarsAreCutAtTheFloorAndMarkedBelowIt) {
  // Values over twelve decades, a zero and one above the rest: at most six
  // decades are shown; every bar lies between floor and top of the frame,
  // and each value under the floor is a triangle on it.
  Figure f("fig-b", 640, 400);
  f.SetYLog(true, 6);
  std::vector<double> x, a, b;
  for (int k = 0; k < 13; ++k) {
    x.push_back(k);
    a.push_back(std::pow(10.0, -k + 2));   // 100 .. 1e-10
    b.push_back(k == 3 ? 0.0 : 3e-3);
  }
  Style sa, sb;
  sb.colour = "#d62728";
  f.Bars(x, a, 0.4, sa, "before", -0.2);
  f.Bars(x, b, 0.4, sb, "after", 0.2);
  Parsed p(f.Svg());
  // The frame: the plot area's clip rectangle.
  const XMLElement* clip = p.svg->FirstChildElement("defs")->FirstChildElement("clipPath")->FirstChildElement("rect");
  const double top = clip->DoubleAttribute("y"), bottom = top + clip->DoubleAttribute("height");
  size_t bars = 0, below = 0;
  Walk(p.svg, [&](const XMLElement* e) {
    const char* c = e->Attribute("class");
    if (c && std::strcmp(c, "bar") == 0) {
      ++bars;
      EXPECT_GE(e->DoubleAttribute("y"), top - 0.05);
      EXPECT_LE(e->DoubleAttribute("y") + e->DoubleAttribute("height"), bottom + 0.05) << "a bar below the floor";
      EXPECT_NEAR(e->DoubleAttribute("y") + e->DoubleAttribute("height"), bottom, 0.1) << "bars start at the floor";
    }
    if (c && std::strcmp(c, "below-floor") == 0) ++below;
  });
  // Top decade 100, floor 1e-4: "before" 1e-5 .. 1e-10 (6 values) and the
  // zero of "after" fall below it.
  EXPECT_EQ(below, 6u + 1u);
  EXPECT_EQ(bars + below, 26u) << "every value is either a bar or a mark on the floor";
  const auto y = Texts(Group(p.svg, "yticks"));
  EXPECT_EQ(y.front(), "1e-04");
  EXPECT_EQ(y.back(), "100");
  // The legend names both series and, per series, what lies under the floor.
  const auto legend = Texts(Group(p.svg, "legend"));
  ASSERT_EQ(legend.size(), 4u);
  EXPECT_EQ(legend[2], "6 below the axis floor 1e-04 (marked on it)");
  EXPECT_EQ(legend[3], "1 below the axis floor 1e-04 (marked on it)");
  EXPECT_TRUE(OutsideViewBox(p.svg).empty());
}

TEST(Figure, ClassHeatmapColoursByBoundsAndLabelsCells) {
  Figure f("fig-c", 600, 400);
  HeatOptions o;
  o.colour_label = "|z| [sigma]";
  o.class_bounds = {2, 5};
  o.class_colours = {"#88cc88", "#ffcc66", "#ee5555"};
  o.value_format = "%.1f";
  std::vector<double> xs{-40, -20, 0}, ys{0, 20}, z{0.5, 2.0, 7.5, 4.9, std::nan(""), 1.0};
  for (size_t k = 0; k < z.size(); ++k) o.cell_titles.push_back("point " + std::to_string(k));
  f.Heatmap(xs, ys, z, o);
  Parsed p(f.Svg());
  std::vector<std::string> fills;
  Walk(p.svg, [&](const XMLElement* e) {
    const char* c = e->Attribute("class");
    if (c && std::strcmp(c, "cell") == 0) {
      fills.push_back(e->Attribute("fill"));
      EXPECT_NE(e->FirstChildElement("title"), nullptr);
    }
  });
  EXPECT_EQ(fills, (std::vector<std::string>{"#88cc88", "#ffcc66", "#ee5555", "#ffcc66", "#88cc88"}))
      << "the NaN cell is left blank";
  EXPECT_EQ(CountClass(p.svg, "cell-label"), 5u);
  const auto bar = Texts(Group(p.svg, "colourbar"));
  EXPECT_EQ(bar, (std::vector<std::string>{"2", "5", "|z| [sigma]"}));
  ExpectRoundTicks(Texts(Group(p.svg, "xticks")), "x axis");
  EXPECT_TRUE(OutsideViewBox(p.svg).empty());
}

// Equal scaling widens one axis; a range symmetric about zero (the whole
// left half of the current plane, both torque directions) stays centred:
// the span added goes half to each end, not all to one.
TEST(Figure, EqualAspectWidensASymmetricRangeOnBothEnds) {
  Figure f("fig-eq", 300, 800);   // tall: the y axis is the one widened
  f.SetXRange(-10, 1);
  f.SetYRange(-10, 10);
  f.SetEqualAspect(true);
  f.SetTight(true, true);
  f.Line({0, 0}, {-10, 10}, Style{}, "");
  Parsed p(f.Svg());
  const XMLElement* clip = nullptr;
  const XMLElement* line = nullptr;
  Walk(p.svg, [&](const XMLElement* e) {
    if (!clip && std::strcmp(e->Name(), "rect") == 0 && e->Parent() &&
        std::strcmp(e->Parent()->ToElement()->Name(), "clipPath") == 0) {
      clip = e;
    }
    const char* c = e->Attribute("class");
    if (!line && c && std::strcmp(c, "line") == 0) line = e;
  });
  ASSERT_NE(clip, nullptr);
  ASSERT_NE(line, nullptr);
  double x0, y_lo, x1, y_hi;   // the line from y = -10 (bottom) to y = 10 (top)
  ASSERT_EQ(std::sscanf(line->Attribute("d"), "M%lf %lf L%lf %lf", &x0, &y_lo, &x1, &y_hi), 4) << line->Attribute("d");
  const double top = clip->DoubleAttribute("y"), bottom = top + clip->DoubleAttribute("height");
  EXPECT_GT(y_hi - top, 20) << "the y axis was widened";
  EXPECT_NEAR(y_hi - top, bottom - y_lo, 1.0) << "as much room above iq = 10 as below iq = -10 (px)";
}

TEST(CoincidentGroups, MergesCurvesOnTopOfEachOther) {
  const std::vector<std::vector<double>> ys{{1, 2, 3}, {1.001, 2, 3}, {1, 2.5, 3}, {1, 2.0005, 2.999}, {1, 2.5, 3.001}};
  EXPECT_EQ(CoincidentGroups(ys, 0.01), (std::vector<size_t>{0, 0, 2, 0, 2}));
  EXPECT_EQ(CoincidentGroups(ys, 1e-6), (std::vector<size_t>{0, 1, 2, 3, 4}));
}

TEST(PanelsSvg, FiguresSideBySideInsideTheOuterBox) {
  std::vector<Figure> panels;
  for (int k = 0; k < 3; ++k) {
    Figure f("panel-" + std::to_string(k), 420, 300);
    f.SetXLabel("x [1]");
    f.Line({0, 1}, {1.0 * k, k + 1.0}, Style{}, "line " + std::to_string(k));
    panels.push_back(f);
  }
  const std::string svg = PanelsSvg("fig-p", "Three panels under one title that is long enough to need two lines in all",
                                    panels, 2);
  Parsed p(svg);
  size_t nested = 0;
  std::set<std::string> clips;
  Walk(p.svg, [&](const XMLElement* e) { nested += std::strcmp(e->Name(), "svg") == 0; });
  EXPECT_EQ(nested, 3u);
  EXPECT_DOUBLE_EQ(p.svg->DoubleAttribute("width"), 840);
  EXPECT_GT(p.svg->DoubleAttribute("height"), 600) << "two rows under the title";
  EXPECT_TRUE(OutsideViewBox(p.svg).empty());
  for (int k = 0; k < 3; ++k) {
    EXPECT_NE(svg.find("id=\"panel-" + std::to_string(k) + "-clip\""), std::string::npos);
  }
}

}  // namespace
}  // namespace fluxcal::plot
