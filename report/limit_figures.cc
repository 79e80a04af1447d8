// The page's operating-limit figures: MTPA and MTPV on the current plane
// with the current and voltage limits, the torque-speed envelope and its
// power, and the field-weakening maps, each drawn by where its operating
// points lie (measured, by symmetry, extrapolated).
#include <algorithm>
#include <cmath>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "physics/speed.h"
#include "plot/plot.h"
#include "report/format.h"
#include "report/internal.h"
#include "tables/tables.h"

namespace fluxcal::report::internal {

// MTPA and MTPV on the current plane, both torque directions, over the
// torque contours and the current and voltage limits; the measured region
// and where the inductance is not positive definite marked.
void CurrentPlaneSection(const PageContext& ctx, Page* page) {
  const fit::Calibration& cal = *ctx.cal;
  const tables::MachineLimits& lim = ctx.lim;
  const Coverage& cov = ctx.cov;
  const PdScan& pd = ctx.pd;
  const bool voltage = ctx.voltage;
  const double ell_rpm = ctx.ell_rpm, ell_we = ctx.ell_we, base_rpm = ctx.base_rpm;
  const std::string& ell_source = ctx.ell_source;
  const std::string& mtpv_note = ctx.mtpv_note;
  const bool mtpv_extrapolated = ctx.mtpv_extrapolated;
  const auto& mtpa = ctx.tabs.at("mtpa");
  const auto& mtpv = ctx.tabs.at("mtpv");
  std::string& b = page->body;
  b += "<section><h2>Operating limits: MTPA, MTPV, current and voltage limit</h2>\n";
  const double im = lim.i_max_a;
  plot::Figure f("fig-plane", 1000, 1000);
  f.SetTitle(voltage ? absl::StrFormat("MTPA and MTPV on the current plane, both torque directions (voltage limit at %s)",
                                       Num(ell_rpm, kSpeedRpm, "rpm"))
                     : std::string("MTPA and MTPV on the current plane, both torque directions (no voltage limit: "
                                   "Udc or Rs not known)"));
  f.SetXLabel("id [A]");
  f.SetYLabel("iq [A]");
  // Wide enough for the MTPV points near the current limit (up to
  // 1.6 i_max); rows farther out are counted in the legend instead.
  double mtpv_id_min = -1.2 * im;
  for (size_t k = 0; k < mtpv.outputs[0].values.size(); ++k) {
    const double d = mtpv.outputs[0].values[k];
    if (mtpv.outputs[2].values[k] > 0 && d >= -1.6 * im) mtpv_id_min = std::min(mtpv_id_min, d);
  }
  const double view_x_lo = mtpv_id_min, view_y = 1.2 * im;
  f.SetXRange(view_x_lo, 0.1 * im);
  f.SetYRange(-view_y, view_y);
  f.SetEqualAspect(true);
  f.SetTight(true, true);
  // Torque contours, current circle and voltage limit: the same drawing
  // as the exported MTPA / MTPV figures (tables::DrawCurrentPlane), over
  // both halves.
  tables::DrawCurrentPlane(&f, cal, lim, -2.5 * im, 2.5 * im, ell_we,
                           absl::StrFormat("voltage limit |u| = %s at %s", Num(lim.UMaxV(), kVoltageV, "V"),
                                           Num(ell_rpm, kSpeedRpm, "rpm")),
                           /*generating=*/true);
  plot::Style region;
  region.colour = "#2ca02c";
  region.width_px = 1.2;
  region.dash = "1 3";
  auto box = [&](double q0, double q1, const plot::Style& st, const std::string& label) {
    f.Line({cov.id_lo, cov.id_hi, cov.id_hi, cov.id_lo, cov.id_lo}, {q0, q0, q1, q1, q0}, st, label);
  };
  box(cov.iq_lo, cov.iq_hi, region,
      absl::StrFormat("measured region (id %s, iq %s)", Range(cov.id_lo, cov.id_hi, kCurrentA, "A"),
                      Range(cov.iq_lo, cov.iq_hi, kCurrentA, "A")));
  if (cov.symmetric && !(cov.MotoringMeasured() && cov.GeneratingMeasured())) {
    plot::Style mirror = region;
    mirror.colour = "#98df8a";
    mirror.dash = "4 4";
    box(-cov.iq_hi, -cov.iq_lo, mirror, "its mirror image (by symmetry)");
  }
  unsigned drawn = 0;
  // A table's rows as a curve through the plane, each stretch drawn by
  // where its rows lie (measured / mirror / extrapolated).
  auto curve = [&](const std::vector<double>& x, const std::vector<double>& y, const std::string& colour,
                   std::string label) -> bool {
    if (x.empty()) return false;   // nothing to draw: the caption says so
    size_t beyond = 0, outside = 0;
    std::vector<Source> src;
    for (size_t k = 0; k < x.size(); ++k) {
      beyond += x[k] < view_x_lo || std::abs(y[k]) > view_y;
      src.push_back(cov.At(x[k], y[k]));
      outside += src.back() == Source::kExtrapolated;
    }
    (void)outside;   // the line's pattern shows it; the caption says why
    label += beyond > 0 ? absl::StrFormat(", %zu beyond the view)", beyond) : std::string(")");
    plot::Style st;
    st.colour = colour;
    st.width_px = 2.5;
    drawn |= LineBySource(&f, x, y, src, st, label);
    return true;
  };
  // MTPA: every row, generating (iq < 0) to motoring, in torque order.
  curve(mtpa.outputs[0].values, mtpa.outputs[1].values, "#d62728",
        absl::StrFormat("MTPA (table: %zu rows", mtpa.outputs[0].values.size()));
  // MTPV: the table's rows (motoring only); rows the solver could not
  // place (no torque, or id at its search bound of -2 i_max) are not
  // points of the curve.
  std::vector<double> vx, vy;
  for (size_t k = 0; k < mtpv.outputs[0].values.size(); ++k) {
    if (!(mtpv.outputs[2].values[k] > 0) || mtpv.outputs[0].values[k] < -1.99 * im) continue;
    vx.push_back(mtpv.outputs[0].values[k]);
    vy.push_back(mtpv.outputs[1].values[k]);
  }
  const bool have_mtpv = curve(vx, vy, "#1f77b4", absl::StrFormat("MTPV (table: %zu rows", vx.size()));
  std::string mtpv_generating;
  if (have_mtpv && cov.symmetric) {
    // The table holds the motoring rows; a symmetric model's generating
    // MTPV is their mirror image.
    std::vector<double> my;
    for (double q : vy) my.push_back(-q);
    std::vector<Source> src;
    for (size_t k = 0; k < vx.size(); ++k) src.push_back(cov.At(vx[k], my[k]));
    plot::Style st;
    st.colour = "#1f77b4";
    st.width_px = 2.5;
    drawn |= LineBySource(&f, vx, my, src, st, "MTPV, generating: the table's rows mirrored");
    mtpv_generating = " The generating MTPV is the table's rows mirrored (the model is symmetric in iq).";
  } else if (have_mtpv) {
    f.Note("generating MTPV: not in the table");
    mtpv_generating = " The MTPV table holds motoring rows only; this model is asymmetric in iq, so its generating "
                      "MTPV is not their mirror image and is not drawn.";
  }
  if (pd.bad > 0) {
    plot::Style x;
    x.marker = plot::Marker::kCross;
    x.colour = "#7f7f7f";
    x.marker_px = 2.5;
    f.Scatter(pd.bad_id, pd.bad_iq, x, absl::StrFormat("not positive definite (%d grid nodes)", pd.bad));
  }
  SourceKey(&f, drawn, cov);
  const std::string voltage_text =
      voltage ? absl::StrFormat("the voltage limit |u| = %s (m Udc / sqrt 3, Udc %s) at %s (%s), ",
                                Num(lim.UMaxV(), kVoltageV, "V"), Num(*lim.udc_v, kVoltageV, "V"),
                                Num(ell_rpm, kSpeedRpm, "rpm"), H(ell_source))
              : std::string("no voltage limit (Udc or Rs not known: see above), ");
  const std::string base_text =
      voltage ? absl::StrFormat(" Base speed at full MTPA torque: %s.", Num(base_rpm, kSpeedRpm, "rpm")) : std::string();
  page->Figure(f, absl::StrCat(
                     "Constant-torque contours from the fitted flux linkage (T = 1.5 p (psi_d iq - psi_q id)), the "
                     "current limit, ", voltage_text, "and the MTPA and MTPV tables' rows, motoring (iq > 0) and "
                     "generating (iq < 0). ", H(cov.OtherHalf()), ".", base_text, H(mtpv_generating),
                     mtpv_extrapolated ? " " + H(mtpv_note) : std::string(),
                     have_mtpv ? "" : " The MTPV table has no row with positive torque to draw."));
  b += "</section>\n";
}

// The torque-speed envelope of the tables library (the `fluxcal export
// --table envelope` table, tables::BuildTable kind "envelope"), over the
// field-weakening table's speeds: at each speed the largest torque within
// both limits, motoring (tm) and generating (tg), and where its operating
// point lies.
absl::StatusOr<Envelope> BuildEnvelope(const PageContext& ctx) {
  const fit::Calibration& cal = *ctx.cal;
  const tables::MachineLimits& lim = ctx.lim;
  const Coverage& cov = ctx.cov;
  Envelope out;
  auto& [env_n, tm, tg, sm, sg] = out;
  if (ctx.voltage) {
    tables::TableSpec es = ctx.spec;
    es.kind = "envelope";
    es.allow_extrapolation = false;
    for (const bool generating : {false, true}) {
      es.envelope_generating = generating;
      auto env = tables::BuildTable(cal, lim, es);
      if (!env.ok()) {
        return absl::InvalidArgumentError(
            absl::StrCat(ctx.in->calibration_path, ": envelope table: ", env.status().message()));
      }
      env_n = env->axes[0].values;
      auto& t = generating ? tg : tm;
      auto& src = generating ? sg : sm;
      t.assign(env_n.size(), 0.0);
      src.assign(env_n.size(), Source::kMeasured);
      for (size_t j = 0; j < env_n.size(); ++j) {
        t[j] = env->outputs[2].values[j];
        src[j] = cov.At(env->outputs[0].values[j], env->outputs[1].values[j]);
      }
    }
  }
  return out;
}

// The envelope's limit torque and power over speed, with the base speed.
void EnvelopeSection(const PageContext& ctx, const Envelope& env, Page* page) {
  const tables::MachineLimits& lim = ctx.lim;
  const Coverage& cov = ctx.cov;
  const double base_rpm = ctx.base_rpm;
  const auto& [env_n, tm, tg, sm, sg] = env;
  std::string& b = page->body;
  b += "<section><h2>Torque-speed envelope</h2>\n";
  if (!ctx.voltage) {
    b += "<p>" + H(ctx.no_voltage) + "</p>\n";
  } else {
    b += "<div class=\"grid\">\n";
    const auto& n = env_n;
    unsigned drawn = 0;
    plot::Figure ft("fig-envelope-torque", 640, 420);
    ft.SetTitle("torque-speed envelope (limit torque)");
    ft.SetXLabel("speed [rpm]");
    ft.SetYLabel("torque [N m]");
    plot::Figure fp("fig-envelope-power", 640, 420);
    fp.SetTitle("power at the limit torque");
    fp.SetXLabel("speed [rpm]");
    fp.SetYLabel("mechanical power [kW]");
    for (plot::Figure* f : {&ft, &fp}) {
      f->SetXRange(n.front(), n.back());
      f->SetTight(true, false);
      f->SetLegendBelow(true);
    }
    std::vector<double> pm, pg;
    for (size_t j = 0; j < n.size(); ++j) {
      // P = T w_mech, w_mech = 2 pi n / 60.
      pm.push_back(tm[j] * physics::RpmToMechanicalRadS(n[j]) / 1e3);
      pg.push_back(tg[j] * physics::RpmToMechanicalRadS(n[j]) / 1e3);
    }
    plot::Style motor, gen;
    motor.colour = "#d62728";
    motor.width_px = 2.2;
    gen.colour = "#1f77b4";
    gen.width_px = 2.2;
    drawn |= LineBySource(&ft, n, tm, sm, motor, "motoring");
    drawn |= LineBySource(&ft, n, tg, sg, gen, "generating");
    LineBySource(&fp, n, pm, sm, motor, "motoring");
    LineBySource(&fp, n, pg, sg, gen, "generating");
    double t_top = 0, p_top = 0;
    for (size_t j = 0; j < n.size(); ++j) {
      t_top = std::max({t_top, std::abs(tm[j]), std::abs(tg[j])});
      p_top = std::max({p_top, std::abs(pm[j]), std::abs(pg[j])});
    }
    plot::Style base;
    base.colour = "#555555";
    base.width_px = 1;
    base.dash = "9 3 2 3";
    const std::string base_label = absl::StrFormat("base speed %s", Num(base_rpm, kSpeedRpm, "rpm"));
    if (base_rpm > 0 && base_rpm < n.back()) {
      ft.Line({base_rpm, base_rpm}, {-1.05 * t_top, 1.05 * t_top}, base, base_label);
      fp.Line({base_rpm, base_rpm}, {-1.05 * p_top, 1.05 * p_top}, base, base_label);
    }
    SourceKey(&ft, drawn, cov);
    SourceKey(&fp, drawn, cov);
    const std::string cap = absl::StrFormat(
        "At each speed of the field-weakening table (%s .. %s, %zu speeds), the largest torque within the current "
        "limit %s and the voltage limit %s (Udc %s): the envelope table (fluxcal export --table envelope), the "
        "limit the field-weakening table clamps to; MTPA below base speed, field weakening and MTPV above.",
        Num(n.front(), kSpeedRpm), Num(n.back(), kSpeedRpm, "rpm"), n.size(), Num(lim.i_max_a, kCurrentA, "A"),
        Num(lim.UMaxV(), kVoltageV, "V"), Num(*lim.udc_v, kVoltageV, "V"));
    page->Figure(ft, H(cap) + ((drawn & 6u) ? " " + H(cov.OtherHalf()) + "." : ""));
    page->Figure(fp, "Mechanical power P = T 2 pi n / 60 at the limit torque of the figure beside it.");
    b += "</div>\n";
  }
  b += "</section>\n";
}

// The fw table's id and iq as heat maps over torque request and speed,
// with the limit torque (the envelope) and the cells off the measured
// region.
void FieldWeakeningSection(const PageContext& ctx, const Envelope& env, Page* page) {
  const Coverage& cov = ctx.cov;
  const auto& tm = env.tm;
  const auto& tg = env.tg;
  std::string& b = page->body;
  b += "<section><h2>Field-weakening map</h2><div class=\"grid\">\n";
  if (!ctx.voltage) {
    b += "<p>" + H(ctx.no_voltage) + "</p>\n";
  } else {
    const auto& fw = ctx.tabs.at("fw");
    const auto& tq = fw.axes[0].values;
    const auto& n = fw.axes[1].values;
    // Where each cell's operating point lies. When the cells off the
    // measured region are exactly the rows of one torque direction (a set
    // measured motoring only), a line at T = 0 and a note say so; else
    // each such cell gets a marker.
    std::vector<Source> cell_src(fw.outputs[0].values.size());
    size_t off = 0, off_gen = 0, gen_cells = 0, off_mirror = 0;
    for (size_t i = 0; i < tq.size(); ++i) {
      for (size_t j = 0; j < n.size(); ++j) {
        const size_t c = i * n.size() + j;
        cell_src[c] = cov.At(fw.outputs[0].values[c], fw.outputs[1].values[c]);
        const bool gen = tq[i] < 0;
        gen_cells += gen;
        if (cell_src[c] != Source::kMeasured) {
          ++off;
          off_gen += gen;
          off_mirror += cell_src[c] == Source::kMirror;
        }
      }
    }
    // (Rows next to T = 0 operate near iq = 0, inside the measured box.)
    const bool whole_half =
        off > 0 && off == off_gen && off_gen >= 0.9 * gen_cells && (off_mirror == 0 || off_mirror == off);
    const double cell_px = std::min(0.75 * 640 / n.size(), 0.75 * 420 / tq.size());
    const double marker = std::clamp(0.3 * cell_px, 1.5, 3.5);
    for (size_t o = 0; o < fw.outputs.size(); ++o) {
      const auto& out = fw.outputs[o];
      const std::string quantity = out.name == "id_a" ? "id" : "iq";
      plot::Figure f("fig-fw-" + out.name, 640, 440);
      f.SetTitle(absl::StrFormat("field weakening: %s", quantity));
      f.SetXLabel("speed [rpm]");
      f.SetYLabel("torque request [N m]");
      f.SetLegendBelow(true);
      plot::HeatOptions opt;
      opt.colour_label = quantity + " [A]";
      std::vector<double> cx, cy, ex, ey;
      for (size_t i = 0; i < tq.size(); ++i) {
        for (size_t j = 0; j < n.size(); ++j) {
          const size_t c = i * n.size() + j;
          opt.cell_titles.push_back(absl::StrFormat("%s, %s: %s = %s%s", Num(tq[i], kTorqueNm, "N m"),
                                                    Num(n[j], kSpeedRpm, "rpm"), quantity,
                                                    Num(out.values[c], kCurrentA, "A"),
                                                    fw.clamped[c] ? ", clamped" : ""));
          if (fw.clamped[c]) cx.push_back(n[j]), cy.push_back(tq[i]);
          if (!whole_half && cell_src[c] != Source::kMeasured) ex.push_back(n[j]), ey.push_back(tq[i]);
        }
      }
      f.Heatmap(n, tq, out.values, std::move(opt));
      // The limit torque per speed (the envelope): requests beyond it are
      // clamped to it. One line instead of a marker on every clamped cell.
      plot::Style under, over;
      under.colour = "#000000";
      under.width_px = 3.4;
      over.colour = "#ffffff";
      over.width_px = 1.4;
      // Where the limit lies beyond the table's torque axis (the cells' outer
      // edges), the line breaks: no request row reaches it there.
      const double half = tq.size() > 1 ? 0.5 * (tq[1] - tq[0]) : 0.5;
      for (const auto* t : {&tm, &tg}) {
        std::vector<double> y = *t;
        for (double& v : y) {
          if (v < tq.front() - half || v > tq.back() + half) v = std::nan("");
        }
        f.Line(n, y, under, "");
        f.Line(n, y, over, "");
      }
      plot::Style key = under;
      key.width_px = 2.4;
      if (!cx.empty()) {
        f.Line({}, {}, key, absl::StrFormat("limit torque: requests beyond it are clamped (%zu of %zu cells)",
                                            cx.size(), fw.clamped.size()));
      } else {
        f.Line({}, {}, key, "limit torque: no request row reaches it (no clamped cell)");
      }
      if (!ex.empty()) {
        plot::Style sq;
        sq.marker = plot::Marker::kSquare;
        sq.colour = "#ffffff";
        sq.halo = "#000000";
        sq.marker_px = marker;
        f.Scatter(ex, ey, sq, absl::StrFormat("operating point outside the measured region (%zu cells)", ex.size()));
      }
      if (whole_half) {
        plot::Style zero;
        zero.colour = "#ffffff";
        zero.width_px = 1.5;
        zero.dash = "6 3";
        f.Line({n.front(), n.back()}, {0, 0}, zero, "");
        f.Note(absl::StrFormat("below T = 0 (dashed): generating rows, %s",
                               off_mirror > 0 ? "by symmetry (mirror of the measured half)"
                                              : "extrapolated (iq < 0 not measured)"));
      }
      page->Figure(f, absl::StrFormat("The fw table's %s (%zu torque rows x %zu speeds, %s) from the tables library; "
                                     "the black-and-white line is the limit torque at each speed (the envelope): "
                                     "cells beyond it hold the limit point.",
                                     H(out.name), tq.size(), n.size(), H(Range(n.front(), n.back(), kSpeedRpm, "rpm"))));
    }
  }
  b += "</div></section>\n";
}

}  // namespace fluxcal::report::internal
