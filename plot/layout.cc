// Where everything of a figure goes before a byte of SVG is written: the
// axis ranges and ticks (linear on round steps, or decades), the margins
// that the tick labels, axis labels and title need, the legend's entries
// and places (a column on the right or rows below), the colour bar's
// scale, the plot area, and equal aspect.
#include <algorithm>
#include <cmath>
#include <tuple>

#include "plot/internal.h"
#include "plot/plot.h"

namespace fluxcal::plot::internal {
namespace {

// Tick density from the figure's size (a label every `per` px).
int TickTarget(double px, double per) { return std::clamp(static_cast<int>(std::lround(px / per)), 3, 10); }

}  // namespace

Render::Render(const Figure& f) : fig(f), clip(f.id_ + "-clip") {
  Ranges();
  Margins();
  LegendLayout();
  ColourBarLayout();
  PlotArea();
  ytext = YLabels();
  // Log axis: positions by decade.
  lyl = fig.y_log_ ? std::log10(yl) : 0, lyh = fig.y_log_ ? std::log10(yh) : 1;
}

// Ranges: given or from the data, then out to whole ticks. A heat map's
// frame hugs its cells instead (ticks inside only), so no empty band;
// so does a tight figure.
void Render::Ranges() {
  auto range = [&](const std::optional<std::pair<double, double>>& fixed, double lo, double hi) {
    return fixed ? *fixed : std::pair<double, double>{lo, hi};
  };
  std::tie(xl, xh) = range(fig.xrange_, fig.have_data_ ? fig.dx_lo_ : 0, fig.have_data_ ? fig.dx_hi_ : 1);
  std::tie(yl, yh) = range(fig.yrange_, fig.have_data_ ? fig.dy_lo_ : 0, fig.have_data_ ? fig.dy_hi_ : 1);
  // Tick density from the figure's size (a label every ~90 px across,
  // ~60 px up), before the exact plot area is known.
  want_x = TickTarget(0.65 * fig.width_px_, 90), want_y = TickTarget(0.8 * fig.height_px_, 60);
  // A frame that hugs its range shows only the ticks inside it: ask for
  // two more so that as many remain.
  hug_x = fig.heat_.has_value() || fig.tight_x_, hug_y = fig.heat_.has_value() || fig.tight_y_;
  xt = NiceTicks(xl, xh, want_x + (hug_x ? 2 : 0));
  if (fig.y_log_) {
    // Whole decades from the positive data (or the fixed range), at most
    // max_decades_ of them below the top.
    double lo = fig.have_pos_ ? fig.pos_lo_ : 1, hi = fig.have_pos_ ? fig.pos_hi_ : 10;
    if (fig.yrange_ && fig.yrange_->first > 0 && fig.yrange_->second > fig.yrange_->first) {
      lo = fig.yrange_->first, hi = fig.yrange_->second;
    }
    int e_hi = static_cast<int>(std::ceil(std::log10(hi) - 1e-9));
    int e_lo = static_cast<int>(std::floor(std::log10(lo) + 1e-9));
    if (e_hi <= e_lo) e_hi = e_lo + 1;
    e_lo = std::max(e_lo, e_hi - std::max(1, fig.max_decades_));
    yl = std::pow(10.0, e_lo);
    yh = std::pow(10.0, e_hi);
    const int every = std::max(1, static_cast<int>(std::ceil((e_hi - e_lo) / static_cast<double>(want_y + 2))));
    for (int e = e_lo; e <= e_hi; e += every) {
      yt.push_back(std::pow(10.0, e));
      ylab.push_back(FormatDecade(e));
    }
  } else {
    yt = NiceTicks(yl, yh, want_y + (hug_y ? 2 : 0));
  }
  if (!fig.heat_ && !fig.tight_x_) xl = xt.front(), xh = xt.back();
  if (!fig.heat_ && !fig.tight_y_ && !fig.y_log_) yl = yt.front(), yh = yt.back();
}

std::vector<std::string> Render::YLabels() const {
  if (fig.y_log_) return ylab;
  std::vector<std::string> out;
  for (double v : yt) out.push_back(FormatTick(v, Step(yt)));
  return out;
}

// Margins from what has to fit: tick labels, axis labels, title, legend.
void Render::Margins() {
  double ylab_w = 0;
  for (const auto& l : YLabels()) ylab_w = std::max(ylab_w, TextWidthPx(l));
  // x tick labels are centred on their tick: the outermost ones reach
  // half their width past the frame, into the margins.
  for (double v : xt) xlab_half = std::max(xlab_half, TextWidthPx(FormatTick(v, Step(xt))) / 2);
  left = std::max(8 + (fig.ylabel_.empty() ? 0 : 18) + ylab_w + 8, xlab_half + 4);
  title_lines =
      fig.title_.empty() ? std::vector<std::string>{} : Wrap(fig.title_, fig.width_px_ - left - 8, title_font);
  top = title_lines.empty() ? 12 : 18 + title_line * (title_lines.size() - 1) + 12;
  base_bottom = 24 + (fig.xlabel_.empty() ? 0 : 18);
}

void Render::LegendLayout() {
  // Legend entries: those added, and for bars under a log axis's floor one
  // for their triangles (the floor is known only now).
  legend = fig.legend_;
  if (fig.y_log_) {
    for (const auto& m : fig.marks_) {
      if (m.kind != Figure::Mark::kBars) continue;
      size_t below = 0;
      for (double v : m.y) below += std::isfinite(v) && v < yl * (1 - 1e-12);
      if (below == 0) continue;
      Style st = m.style;
      st.marker = Marker::kTriangleDown;
      st.marker_px = 3;
      st.halo.clear();
      legend.push_back({Figure::LegendEntry::kMarker,
                        Fmt("%.0f", static_cast<double>(below)) + " below the axis floor " +
                            FormatDecade(static_cast<int>(std::lround(std::log10(yl)))) + " (marked on it)",
                        st});
    }
  }
  // Legend on the right in columns of as many entries as the height holds,
  // or below the axes in rows as wide as the figure.
  legend_top = top + 8;
  for (const auto& e : legend) {
    entry_w.push_back(e.kind == Figure::LegendEntry::kNote ? TextWidthPx(e.label) : 30 + TextWidthPx(e.label));
  }
  per_col = std::max<size_t>(1, static_cast<size_t>(std::floor((fig.height_px_ - 8 - legend_top) / entry_h)) + 1);
  if (fig.legend_below_) {
    double x = 0;
    size_t row = 0;
    for (double w : entry_w) {
      if (x > 0 && x + w > fig.width_px_ - 16) ++row, x = 0;
      below_at.push_back({x, row});
      x += w + 18;
    }
    below_rows = legend.empty() ? 0 : row + 1;
  } else {
    for (size_t k = 0; k < legend.size(); ++k) {
      if (k % per_col == 0) col_w.push_back(0);
      col_w.back() = std::max(col_w.back(), entry_w[k]);
    }
  }
  for (double w : col_w) legend_w += w + 12;
  bottom = base_bottom + (below_rows > 0 ? 6 + entry_h * below_rows : 0);
}

void Render::ColourBarLayout() {
  classes = fig.heat_ && !fig.heat_->options.class_bounds.empty();
  // The colour scale runs from the bar's first to its last tick, so that
  // both ends are labelled and every label is a round number.
  if (!fig.heat_) return;
  bar_ticks = classes ? fig.heat_->options.class_bounds : NiceTicks(fig.heat_->lo, fig.heat_->hi, want_y);
  if (!classes) c_lo = bar_ticks.front(), c_hi = bar_ticks.back();
  double tw = 0;
  for (double v : bar_ticks) {
    tw = std::max(tw, TextWidthPx(classes ? Fmt("%g", v) : FormatTick(v, Step(bar_ticks))));
  }
  bar_w = 16 + 14 + 6 + tw + 22;   // gap, bar, tick, labels, rotated title
}

void Render::PlotArea() {
  right = std::max(12 + bar_w + legend_w, xlab_half + 4);
  pw = std::max(40.0, fig.width_px_ - left - right), ph = std::max(40.0, fig.height_px_ - top - bottom);
  if (!fig.equal_aspect_ || fig.y_log_) return;
  // Widen whichever axis has fewer units per pixel, at its end farther
  // from zero (a quadrant plot stays a quadrant plot); a range symmetric
  // about zero on both ends alike (a half plane stays centred).
  const double sx = (xh - xl) / pw, sy = (yh - yl) / ph;
  auto widen = [](double* lo, double* hi, double span) {
    const double extra = span - (*hi - *lo);
    if (std::abs(*hi + *lo) <= 1e-9 * (*hi - *lo)) {
      *hi += extra / 2;
      *lo -= extra / 2;
    } else if (std::abs(*hi) >= std::abs(*lo)) {
      *hi += extra;
    } else {
      *lo -= extra;
    }
  };
  if (sx > sy) widen(&yl, &yh, sx * ph); else widen(&xl, &xh, sy * pw);
  xt = NiceTicks(xl, xh, TickTarget(pw, 80) + (hug_x ? 2 : 0));
  yt = NiceTicks(yl, yh, TickTarget(ph, 60) + (hug_y ? 2 : 0));
  // Same scale, same step: the finer of the two on both axes.
  const double step = std::min(Step(xt), Step(yt));
  auto with_step = [step](double lo, double hi) {
    std::vector<double> t;
    for (double v = std::floor(lo / step + 1e-9) * step; v <= hi + 1e-9 * step && t.size() < 200; v += step) {
      t.push_back(std::abs(v) < 1e-9 * step ? 0.0 : v);
    }
    return t;
  };
  xt = with_step(xl, xh);
  yt = with_step(yl, yh);
}

}  // namespace fluxcal::plot::internal
