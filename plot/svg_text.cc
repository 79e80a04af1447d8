// SVG text primitives: numbers and coordinates as text, escaping, label
// widths and word wrap, marker shapes, and a text colour that reads on a
// fill.
#include <cstdio>

#include "plot/internal.h"
#include "plot/plot.h"

namespace fluxcal::plot {

std::string Escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '&': o += "&amp;"; break;
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

namespace internal {

std::string Fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::string Px(double v) { return Fmt("%.1f", v); }

double TextWidthPx(const std::string& s, double font_px) { return 0.62 * font_px * s.size(); }

double Step(const std::vector<double>& t) { return t.size() > 1 ? t[1] - t[0] : 1.0; }

std::string MarkerSvg(const Style& st, double cx, double cy, const std::string& cls) {
  const double r = st.marker_px;
  const std::string c = st.colour;
  auto shape = [&](const std::string& colour, double extra, bool main) {
    const std::string klass = main ? " class=\"" + cls + "\"" : " class=\"halo\"";
    const std::string sw = Px((main ? 1.6 : 1.6 + 2 * extra));
    switch (st.marker) {
      case Marker::kDot:
        return "<circle" + klass + " cx=\"" + Px(cx) + "\" cy=\"" + Px(cy) + "\" r=\"" + Px(r) + "\" fill=\"" + c +
               (st.halo.empty() ? std::string("\"") : "\" stroke=\"" + st.halo + "\" stroke-width=\"0.6\"") + "/>\n";
      case Marker::kRing:
        return "<circle" + klass + " cx=\"" + Px(cx) + "\" cy=\"" + Px(cy) + "\" r=\"" + Px(r) +
               "\" fill=\"none\" stroke=\"" + colour + "\" stroke-width=\"" + sw + "\"/>\n";
      case Marker::kCross:
        return "<path" + klass + " d=\"M" + Px(cx - r) + " " + Px(cy - r) + " L" + Px(cx + r) + " " + Px(cy + r) +
               " M" + Px(cx - r) + " " + Px(cy + r) + " L" + Px(cx + r) + " " + Px(cy - r) + "\" stroke=\"" +
               colour + "\" stroke-width=\"" + sw + "\" stroke-linecap=\"round\"/>\n";
      case Marker::kSquare:
        return "<rect" + klass + " x=\"" + Px(cx - r) + "\" y=\"" + Px(cy - r) + "\" width=\"" + Px(2 * r) +
               "\" height=\"" + Px(2 * r) + "\" fill=\"none\" stroke=\"" + colour + "\" stroke-width=\"" + sw +
               "\"/>\n";
      case Marker::kTriangleDown:
        return "<path" + klass + " d=\"M" + Px(cx - r) + " " + Px(cy - r) + " L" + Px(cx + r) + " " + Px(cy - r) +
               " L" + Px(cx) + " " + Px(cy + r) + " Z\" fill=\"" + (main ? colour : std::string("none")) +
               "\" stroke=\"" + colour + "\" stroke-width=\"" + (main ? std::string("0.8") : sw) +
               "\" stroke-linejoin=\"round\"/>\n";
    }
    return std::string();
  };
  std::string s;
  if (st.marker != Marker::kDot && !st.halo.empty()) s += shape(st.halo, 1.0, false);
  return s + shape(c, 0, true);
}

std::vector<std::string> Wrap(const std::string& text, double max_px, double font_px) {
  std::vector<std::string> lines;
  std::string cur;
  size_t at = 0;
  while (at <= text.size()) {
    size_t sp = text.find(' ', at);
    if (sp == std::string::npos) sp = text.size();
    const std::string word = text.substr(at, sp - at);
    const std::string cand = cur.empty() ? word : cur + " " + word;
    if (!cur.empty() && TextWidthPx(cand, font_px) > max_px) {
      lines.push_back(cur);
      cur = word;
    } else {
      cur = cand;
    }
    at = sp + 1;
  }
  if (!cur.empty()) lines.push_back(cur);
  return lines;
}

std::string TextOn(const std::string& fill) {
  unsigned r = 0, g = 0, b = 0;
  if (fill.size() == 7 && std::sscanf(fill.c_str() + 1, "%2x%2x%2x", &r, &g, &b) == 3) {
    return 0.299 * r + 0.587 * g + 0.114 * b < 140 ? "#fff" : "#000";
  }
  return "#000";
}

}  // namespace internal
}  // namespace fluxcal::plot
