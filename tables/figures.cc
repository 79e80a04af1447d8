// The tables' SVG figures (tables/tables.h, drawn with plot/): the current
// plane with the MTPA / MTPV curves and the limits, and the
// field-weakening map as a heat map.
#include <algorithm>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "physics/speed.h"
#include "plot/plot.h"
#include "tables/internal_numeric.h"
#include "tables/tables.h"

namespace fluxcal::tables {
namespace {

using internal::Linspace;

constexpr double kPi = std::numbers::pi;

double RpmOf(double we_rad_s, int pole_pairs) { return physics::ElectricalRadSToRpm(we_rad_s, pole_pairs); }

// Speed [rad/s electrical] at which the voltage limit passes through (id,
// iq): the voltage grows with speed there. 0 when no speed reaches it (the
// resistive drop alone exceeds u_max).
double SpeedAtVoltageLimitRadS(const sim::MagneticModel& m, const MachineLimits& lim, double id, double iq) {
  double lo = 0, hi = 1e6;
  if (VoltageV(m, lim, id, iq, lo) >= lim.UMaxV()) return 0;
  if (VoltageV(m, lim, id, iq, hi) < lim.UMaxV()) return hi;
  for (int k = 0; k < 80; ++k) {
    const double mid = 0.5 * (lo + hi);
    (VoltageV(m, lim, id, iq, mid) < lim.UMaxV() ? lo : hi) = mid;
  }
  return lo;
}

// Base speed: where the MTPA point of the largest motoring torque meets the
// voltage limit (bisection; the voltage grows with speed there). 0 when the
// limit is below the resistive drop already at standstill.
double BaseSpeedRadS(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpa) {
  size_t kmax = 0;
  for (size_t k = 0; k < mtpa.axes[0].values.size(); ++k) {
    if (mtpa.axes[0].values[k] > mtpa.axes[0].values[kmax]) kmax = k;
  }
  return SpeedAtVoltageLimitRadS(m, lim, mtpa.outputs[0].values[kmax], mtpa.outputs[1].values[kmax]);
}

// The motoring rows of an MTPA or MTPV table as points of its curve, with
// their flags. MTPV rows the solver could not place (no torque, or id at
// its search bound of -2 i_max) are not points of the curve.
struct CurvePoints {
  std::vector<double> id, iq, cid, ciq, eid, eiq;   // all; clamped; extrapolated
  size_t rows = 0;
};
CurvePoints MotoringRows(const Table& t) {
  CurvePoints c;
  if (t.outputs.size() < 2) return c;
  const double im = t.limits.i_max_a;
  for (size_t k = 0; k < t.outputs[0].values.size(); ++k) {
    const double id = t.outputs[0].values[k], iq = t.outputs[1].values[k];
    if (iq < 0) continue;
    if (t.kind == "mtpv" && (t.outputs.size() < 3 || !(t.outputs[2].values[k] > 0) || id < -1.99 * im)) continue;
    c.id.push_back(id);
    c.iq.push_back(iq);
    if (k < t.clamped.size() && t.clamped[k]) c.cid.push_back(id), c.ciq.push_back(iq);
    if (k < t.extrapolated.size() && t.extrapolated[k]) c.eid.push_back(id), c.eiq.push_back(iq);
  }
  c.rows = c.id.size();
  return c;
}

// Marker styles shared by the curve and map figures: clamped (the request
// exceeded the limits) and extrapolated (beyond the measured current
// limit) must not look like valid entries.
plot::Style MarkStyle(plot::Marker marker, const char* colour, const char* halo, double size_px) {
  plot::Style s;
  s.marker = marker;
  s.colour = colour;
  s.halo = halo;
  s.marker_px = size_px;
  return s;
}
plot::Style ClampedStyle(double size_px) { return MarkStyle(plot::Marker::kCross, "#000000", "#ffffff", size_px); }
plot::Style ExtrapolatedStyle(double size_px) {
  return MarkStyle(plot::Marker::kSquare, "#ffffff", "#000000", size_px);
}


// The speed whose voltage limit a curves figure draws (0: none), the
// legend's reason for it, or why none is drawn.
struct VoltageLimitSpeed {
  double rpm = 0;
  std::string why, no_voltage, unknown_voltage;
};
// The voltage limit at a speed that explains the subject. MTPA: 1.5 x
// base speed, rounded to two digits, far enough into field weakening that
// it cuts the current circle. MTPV: the speed at which MTPV operation
// begins, where the limit passes through the MTPV row of largest current
// within the current limit (its point on the circle, if it reaches it).
VoltageLimitSpeed ChooseVoltageLimitSpeed(const sim::MagneticModel& m, const MachineLimits& lim, const Table* mtpa,
                                          const CurvePoints& pv, bool mtpv_subject) {
  const double im = lim.i_max_a;
  VoltageLimitSpeed v;
  double& rpm = v.rpm;
  std::string& why = v.why;
  std::string& no_voltage = v.no_voltage;
  std::string& unknown_voltage = v.unknown_voltage;
  if (!lim.HasVoltageLimit()) {
    unknown_voltage = absl::StrCat("no voltage limit drawn: ", !lim.udc_v ? "the DC-link voltage (--udc-v)" : "",
                                   !lim.udc_v && !lim.rs_ohm ? " and " : "", !lim.rs_ohm ? "Rs (--rs-ohm)" : "",
                                   " not known");
  } else if (!mtpv_subject) {
    const double we_base = BaseSpeedRadS(m, lim, *mtpa);
    if (we_base > 0) {
      const double raw = 1.5 * RpmOf(we_base, lim.pole_pairs);
      const double mag = std::pow(10.0, std::floor(std::log10(std::max(raw, 1.0))) - 1);
      rpm = std::round(raw / mag) * mag;
      why = absl::StrFormat(" (1.5 x base speed %.0f rpm)", RpmOf(we_base, lim.pole_pairs));
    } else {
      no_voltage = "below the resistive drop at full MTPA current";
    }
  } else {
    int start = -1;
    for (size_t k = 0; k < pv.rows; ++k) {
      const double i = std::hypot(pv.id[k], pv.iq[k]);
      if (i <= im * (1 + 1e-9) && (start < 0 || i > std::hypot(pv.id[start], pv.iq[start]))) {
        start = static_cast<int>(k);
      }
    }
    if (start >= 0) {
      const double we_start = SpeedAtVoltageLimitRadS(m, lim, pv.id[start], pv.iq[start]);
      if (we_start > 0) {
        rpm = RpmOf(we_start, lim.pole_pairs);
        why = absl::StrFormat(", where MTPV begins (its row at |i| = %.4g A)", std::hypot(pv.id[start], pv.iq[start]));
      } else {
        no_voltage = "below the resistive drop at the MTPV rows";
      }
    } else {
      no_voltage.clear();   // said below: no MTPV row inside the current limit
    }
  }
  return v;
}

// The tables' rows over the view [x_lo, x_hi] x [0, y_hi] of `f`, and the
// subject's clamped and extrapolated rows (`meas`: the measured current
// limit its legend names).
void DrawRows(plot::Figure& f, const CurvePoints& pa, const CurvePoints& pv, const Table* mtpv, bool mtpv_subject,
              double x_lo, double x_hi, double y_hi, double meas) {
  auto beyond = [&](const CurvePoints& c) {
    size_t n = 0;
    for (size_t k = 0; k < c.rows; ++k) n += c.id[k] < x_lo || c.iq[k] > y_hi;
    return n == 0 ? std::string() : absl::StrFormat(", %zu beyond the view", n);
  };
  // The tables as lines through their rows, MTPA red, MTPV blue; the
  // subject bold with each row a dot sized to the rows' spacing (dense rows
  // would merge into a thick line), the other thin.
  const double px_per_a = 700 / std::max(x_hi - x_lo, y_hi);   // about the plot area's width
  size_t clamped = 0, extrapolated = 0;
  auto draw = [&](const CurvePoints& c, const std::string& colour, bool is_subject, const std::string& label) {
    plot::Style line;
    line.colour = colour;
    line.width_px = is_subject ? 2.6 : 1.4;
    f.Line(c.id, c.iq, line, is_subject ? label : label + ", for reference");
    if (!is_subject) return;
    double length = 0;
    for (size_t k = 1; k < c.rows; ++k) length += std::hypot(c.id[k] - c.id[k - 1], c.iq[k] - c.iq[k - 1]);
    plot::Style rows = line;
    rows.halo.clear();
    rows.marker_px = std::clamp(0.3 * length * px_per_a / std::max<size_t>(1, c.rows - 1), 1.2, 3.0);
    f.Scatter(c.id, c.iq, rows, "");
    clamped += c.cid.size();
    extrapolated += c.eid.size();
  };
  if (pa.rows > 0) {
    draw(pa, "#d62728", !mtpv_subject,
         absl::StrFormat("MTPA table (%zu motoring rows%s)", pa.rows, beyond(pa)));
  }
  if (pv.rows > 0) {
    const auto& psi = mtpv->axes[0].values;
    draw(pv, "#1f77b4", mtpv_subject,
         absl::StrFormat("MTPV table (%zu rows, |psi| %.3g .. %.3g Wb%s)", pv.rows, psi.front(), psi.back(),
                         beyond(pv)));
  } else {
    f.Note(mtpv == nullptr ? "no MTPV table given" : "the MTPV table has no row with positive torque to draw");
  }
  // The subject's flags on top of the rows they concern.
  std::vector<double> fx, fy, ex, ey;
  for (const CurvePoints* c : {mtpv_subject ? &pv : &pa}) {
    fx.insert(fx.end(), c->cid.begin(), c->cid.end());
    fy.insert(fy.end(), c->ciq.begin(), c->ciq.end());
    ex.insert(ex.end(), c->eid.begin(), c->eid.end());
    ey.insert(ey.end(), c->eiq.begin(), c->eiq.end());
  }
  if (clamped > 0) {
    f.Scatter(fx, fy, ClampedStyle(4), absl::StrFormat("clamped rows (%zu): beyond the limits", clamped));
  }
  if (extrapolated > 0) {
    f.Scatter(ex, ey, ExtrapolatedStyle(4),
              absl::StrFormat("extrapolated rows (%zu): |i| beyond the measured %.4g A", extrapolated, meas));
  }
}

// The current plane with both tables; `mtpv_subject` decides whose figure
// it is: that table is drawn bold with a dot per row and the voltage limit
// at the speed that explains it, the other thin, for reference.
std::string CurvesFigure(const sim::MagneticModel& m, const MachineLimits& lim, const Table* mtpa, const Table* mtpv,
                         bool mtpv_subject) {
  const double im = lim.i_max_a;
  const Table& subject = mtpv_subject ? *mtpv : *mtpa;
  const CurvePoints pa = mtpa != nullptr ? MotoringRows(*mtpa) : CurvePoints{};
  const CurvePoints pv = mtpv != nullptr ? MotoringRows(*mtpv) : CurvePoints{};
  // View: the motoring quadrant of the current limit, widened to the MTPV
  // points up to 1.6 i_max (MTPV usually lies at id < -i_max); rows beyond
  // are counted in the legend.
  double x_lo = -1.1 * im;
  for (double d : pv.id) {
    if (d >= -1.6 * im) x_lo = std::min(x_lo, 1.05 * d);
  }
  const double x_hi = 0.1 * im, y_hi = 1.15 * im;
  plot::Figure f(mtpv_subject ? "mtpv-curves" : "mtpa-curves", 820, 860);
  // Below the axes: the equal-aspect view wants the width, the legend
  // names speeds, limits and row counts.
  f.SetLegendBelow(true);
  f.SetTitle(absl::StrFormat("%s%s%s table on the current plane (motoring half)%s", subject.serial,
                             subject.serial.empty() ? "" : ": ", mtpv_subject ? "MTPV" : "MTPA",
                             (mtpv_subject ? mtpa : mtpv) != nullptr
                                 ? (mtpv_subject ? ", MTPA for reference" : ", MTPV for reference")
                                 : ""));
  f.SetXLabel("id [A]");
  f.SetYLabel("iq [A]");
  f.SetXRange(x_lo, x_hi);
  f.SetYRange(0, y_hi);
  f.SetEqualAspect(true);
  f.SetTight(true, true);
  // Fields sampled well beyond the view (equal scaling widens one axis);
  // the figure clips the lines at its frame.
  const double field_id_lo_a = std::min(x_lo, -2.0 * im) - 0.2 * im, field_iq_hi_a = 2.2 * im;
  const VoltageLimitSpeed voltage_limit = ChooseVoltageLimitSpeed(m, lim, mtpa, pv, mtpv_subject);
  const double rpm = voltage_limit.rpm;
  const std::string& why = voltage_limit.why;
  const std::string& no_voltage = voltage_limit.no_voltage;
  const std::string& unknown_voltage = voltage_limit.unknown_voltage;
  const double we = physics::RpmToElectricalRadS(rpm, lim.pole_pairs);
  const PlaneCircle circle = DrawCurrentPlane(
      &f, m, lim, field_id_lo_a, field_iq_hi_a, rpm > 0 ? we : 0.0,
      absl::StrFormat("voltage limit |u| = %.3g V at %.0f rpm%s", lim.UMaxV(), rpm, why));
  const std::vector<double>& cx = circle.id_a;
  const std::vector<double>& cy = circle.iq_a;
  const double meas = subject.measured_current_limit_a;
  if (meas > 0 && std::abs(meas - im) > 1e-6 * im) {
    plot::Style mc;
    mc.colour = "#2ca02c";
    mc.width_px = 1.2;
    mc.dash = "2 3";
    std::vector<double> mx, my;
    for (double x : cx) mx.push_back(x * meas / im);
    for (double y : cy) my.push_back(y * meas / im);
    f.Line(mx, my, mc, absl::StrFormat("measured current limit %.4g A", meas));
  }
  if (rpm > 0) {
    // drawn with the plane (DrawCurrentPlane)
  } else if (!unknown_voltage.empty()) {
    f.Note(unknown_voltage);
  } else if (!no_voltage.empty()) {
    f.Note(absl::StrFormat("no voltage limit drawn: u_max %.3g V is %s", lim.UMaxV(), no_voltage));
  } else {
    f.Note("no voltage limit drawn: no MTPV row lies inside the current limit");
  }
  DrawRows(f, pa, pv, mtpv, mtpv_subject, x_lo, x_hi, y_hi, meas);
  return f.Svg();
}

}  // namespace

PlaneCircle DrawCurrentPlane(plot::Figure* f, const sim::MagneticModel& m, const MachineLimits& lim, double id_lo_a,
                             double iq_hi_a, double we_rad_s, const std::string& voltage_label, bool generating) {
  const double im = lim.i_max_a;
  if (!lim.HasVoltageLimit()) we_rad_s = 0;   // no voltage limit without Udc and Rs
  const auto xs = Linspace(id_lo_a, 0.6 * im, 161);
  const auto ys = generating ? Linspace(-iq_hi_a, iq_hi_a, 241) : Linspace(-0.2 * im, iq_hi_a, 121);
  std::vector<double> tz, uz;
  double tmax = 0, tmin = 0;
  for (double iq : ys) {
    for (double id : xs) {
      const double t = TorqueNm(m, lim.pole_pairs, id, iq, lim.temperature_c);
      tz.push_back(t);
      if (we_rad_s > 0) uz.push_back(VoltageV(m, lim, id, iq, we_rad_s));
      if (std::hypot(id, iq) <= im) tmax = std::max(tmax, t), tmin = std::min(tmin, t);
    }
  }
  // Torque contours at round values inside the current limit's torque
  // (and, generating, the same steps below zero down to its torque there).
  std::vector<double> levels;
  const auto ticks = plot::NiceTicks(0, tmax, 6);
  for (double v : ticks) {
    if (v > 0 && v <= tmax) levels.push_back(v);
  }
  if (generating && ticks.size() > 1) {
    const double step = ticks[1] - ticks[0];
    for (double v = -step; v >= tmin - 1e-9 * step; v -= step) levels.push_back(v);
  }
  plot::Style contour;
  contour.colour = "#888888";
  contour.width_px = 1;
  f->Contours(xs, ys, tz, levels, contour, "constant torque [N m] (labelled)", "%g");
  plot::Style circle;
  circle.colour = "#000000";
  circle.dash = "6 4";
  PlaneCircle c;
  const int n = generating ? 240 : 120;
  for (int k = 0; k <= n; ++k) {
    const double a = kPi / 2 + kPi / 2 * k / 120;
    c.id_a.push_back(im * std::cos(a));
    c.iq_a.push_back(im * std::sin(a));
  }
  f->Line(c.id_a, c.iq_a, circle, absl::StrFormat("current limit |i| = %.4g A", im));
  if (we_rad_s > 0) {
    plot::Style volt;
    volt.colour = "#ff7f0e";
    volt.width_px = 2;
    volt.dash = "2 3";
    f->Contours(xs, ys, uz, {lim.UMaxV()}, volt, voltage_label, "");
  }
  return c;
}

std::string PlotCurvesSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpa,
                          const Table* mtpv) {
  return CurvesFigure(m, lim, &mtpa, mtpv, false);
}

std::string PlotMtpvSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpv,
                        const Table* mtpa) {
  return CurvesFigure(m, lim, mtpa, &mtpv, true);
}

std::string PlotMapSvg(const Table& fw, const std::string& output_name) {
  const Output* o = nullptr;
  for (const auto& out : fw.outputs) if (out.name == output_name) o = &out;
  if (o == nullptr || fw.axes.size() != 2) return "";
  const auto& tq = fw.axes[0].values;   // rows (slowest)
  const auto& n = fw.axes[1].values;    // columns
  if (tq.empty() || n.empty() || o->values.size() != tq.size() * n.size()) return "";
  const std::string quantity = output_name.substr(0, output_name.rfind('_'));
  const double width = 900, height = 640;
  plot::Figure f("fw-map", width, height);
  // Below the axes: the map gets the width.
  f.SetLegendBelow(true);
  f.SetTitle(absl::StrFormat("%s%sfield-weakening table: %s over speed and torque request", fw.serial,
                             fw.serial.empty() ? "" : ": ", quantity));
  f.SetXLabel(absl::StrFormat("speed [%s]", UnitOf(fw.axes[1].name)));
  const std::string torque_unit = UnitOf(fw.axes[0].name);
  f.SetYLabel(absl::StrFormat("torque request [%s]", torque_unit == "Nm" ? "N m" : torque_unit));
  plot::HeatOptions opt;
  opt.colour_label = absl::StrFormat("%s [%s]", quantity, UnitOf(output_name));
  std::vector<double> cx, cy, ex, ey;
  for (size_t i = 0; i < tq.size(); ++i) {
    for (size_t j = 0; j < n.size(); ++j) {
      const size_t k = i * n.size() + j;
      const bool c = k < fw.clamped.size() && fw.clamped[k], e = k < fw.extrapolated.size() && fw.extrapolated[k];
      opt.cell_titles.push_back(absl::StrFormat("%.4g N m, %.0f rpm: %s = %.4g %s%s%s", tq[i], n[j], quantity,
                                                o->values[k], UnitOf(output_name), c ? ", clamped" : "",
                                                e ? ", extrapolated" : ""));
      if (c) cx.push_back(n[j]), cy.push_back(tq[i]);
      if (e) ex.push_back(n[j]), ey.push_back(tq[i]);
    }
  }
  // The table is row-major over (torque, speed): speed is the grid's x.
  f.Heatmap(n, tq, o->values, std::move(opt));
  // Markers sized to the cells (the plot area is about 80 % x 75 % of the
  // figure), so that one marks one cell and leaves its colour visible.
  const double cell_px = std::min(0.8 * width / n.size(), 0.75 * height / tq.size());
  const double size = std::clamp(0.3 * cell_px, 1.5, 4.0);
  if (!cx.empty()) {
    f.Scatter(cx, cy, ClampedStyle(size), absl::StrFormat("clamped (%zu cells): request beyond the limits", cx.size()));
  } else {
    f.Note("no clamped cell");
  }
  if (!ex.empty()) {
    f.Scatter(ex, ey, ExtrapolatedStyle(size),
              absl::StrFormat("extrapolated (%zu cells): |i| beyond the measured %.4g A", ex.size(),
                              fw.measured_current_limit_a));
  } else {
    f.Note(fw.measured_current_limit_a > 0 ? "no extrapolated cell" : "extrapolation not checked (no measured limit)");
  }
  return f.Svg();
}

namespace {

// Where a cell's operating point stands: 0 measured, 1 by symmetry,
// 2 extrapolated.
int RegionClass(const Table& t, size_t k) {
  if (k < t.extrapolated.size() && t.extrapolated[k]) return 2;
  if (k < t.by_symmetry.size() && t.by_symmetry[k]) return 1;
  return 0;
}

// The report page's key (plot::ProvenanceDash), indexed by region class
// (0 measured, 1 by symmetry, 2 extrapolated).
const char* RegionDash(int cls) { return plot::ProvenanceDash(static_cast<plot::Provenance>(cls)); }

// One envelope output (torque or power) over speed as one curve per table:
// each run of speeds of one region class drawn in its own dash, joined to
// the next run at their shared speed so that the curve has no gap; clamped
// speeds (no torque) are left out.
void EnvelopeCurves(plot::Figure* f, const std::vector<Table>& envs, const std::string& output, double scale) {
  for (size_t i = 0; i < envs.size(); ++i) {
    const Table& t = envs[i];
    const Output* o = nullptr;
    for (const auto& out : t.outputs) if (out.name == output) o = &out;
    if (o == nullptr || t.axes.size() != 1) continue;
    const auto& n = t.axes[0].values;
    const std::string label = t.limits.udc_v ? absl::StrFormat("Udc %.4g V", *t.limits.udc_v) : "envelope";
    bool labelled = false;
    size_t k = 0;
    while (k < n.size()) {
      if (k < t.clamped.size() && t.clamped[k]) { ++k; continue; }
      const int cls = RegionClass(t, k);
      std::vector<double> x, y;
      size_t e = k;
      while (e < n.size() && !(e < t.clamped.size() && t.clamped[e]) && RegionClass(t, e) == cls) {
        x.push_back(n[e]);
        y.push_back(o->values[e] * scale);
        ++e;
      }
      // Joined to the next run (its first point) when that is drawn too.
      if (e < n.size() && !(e < t.clamped.size() && t.clamped[e])) {
        x.push_back(n[e]);
        y.push_back(o->values[e] * scale);
      }
      plot::Style st;
      st.colour = plot::Palette(static_cast<int>(i));
      st.width_px = 2.0;
      st.dash = RegionDash(cls);
      // One legend entry per Udc, on its first solid stretch, or its first
      // stretch when none is solid.
      bool any_solid = false;
      for (size_t q = 0; q < n.size(); ++q) {
        if (!(q < t.clamped.size() && t.clamped[q]) && RegionClass(t, q) == 0) any_solid = true;
      }
      const bool take = !labelled && (cls == 0 || !any_solid);
      if (x.size() == 1) {
        f->Scatter(x, y, st, take ? label : "");
      } else {
        f->Line(x, y, st, take ? label : "");
      }
      labelled |= take;
      k = e;
    }
  }
}

}  // namespace

std::string PlotEnvelopeSvg(const std::vector<Table>& envs) {
  if (envs.empty()) return "";
  const Table& t0 = envs.front();
  plot::Figure torque("envelope-torque", 620, 440), power("envelope-power", 620, 440);
  // The generating envelope: the largest braking torque (drawn negative).
  const bool gen = t0.envelope_generating;
  torque.SetTitle(gen ? "generating limit: torque over speed" : "maximum torque over speed");
  torque.SetXLabel("speed [rpm]");
  torque.SetYLabel("torque [N m]");
  power.SetTitle(gen ? "generating limit: power over speed" : "maximum power over speed");
  power.SetXLabel("speed [rpm]");
  power.SetYLabel("power [kW]");
  for (plot::Figure* f : {&torque, &power}) {
    f->SetLegendBelow(true);
    f->SetXRange(0, t0.speed_max_rpm > 0 ? t0.speed_max_rpm : 1);
  }
  EnvelopeCurves(&torque, envs, "torque_nm", 1.0);
  EnvelopeCurves(&power, envs, "power_w", 1e-3);
  // What the dashes mean, and what is not drawn.
  size_t ext = 0, sym = 0, none = 0;
  for (const auto& t : envs) {
    for (size_t k = 0; k < t.clamped.size(); ++k) {
      if (t.clamped[k]) { ++none; continue; }
      const int c = RegionClass(t, k);
      ext += c == 2;
      sym += c == 1;
    }
  }
  plot::Style ex, sy;
  ex.colour = sy.colour = "#555555";
  ex.dash = RegionDash(2);
  sy.dash = RegionDash(1);
  for (plot::Figure* f : {&torque, &power}) {
    if (ext > 0) {
      f->Line({}, {}, ex, absl::StrFormat("dotted: extrapolated (%zu points), not measured", ext));
    }
    if (sym > 0) f->Line({}, {}, sy, absl::StrFormat("dashed: by symmetry (%zu points), mirror of the measured half", sym));
    f->Note(ext + sym > 0 ? "solid: measured region" : "every point in the measured region");
    if (none > 0) f->Note(absl::StrFormat("%zu speeds without torque (beyond reach) not drawn", none));
  }
  const auto& l = t0.limits;
  const std::string title = absl::StrFormat(
      "%s%s%storque-speed and power-speed envelope: current limit %.4g A, Rs %.4g ohm, u_max = %.3g x Udc / sqrt 3 "
      "(linear SVPWM)%s",
      t0.serial, t0.serial.empty() ? "" : ": ", gen ? "generating " : "", l.i_max_a, l.rs_ohm.value_or(0.0), l.modulation_limit,
      t0.magnet_temperature ? absl::StrFormat(", magnets at %.4g degC", t0.magnet_temperature->at_c) : "");
  return plot::PanelsSvg("envelope", title, {torque, power}, 2);
}

}  // namespace fluxcal::tables
