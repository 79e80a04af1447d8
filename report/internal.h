// The report page's own parts (not a public API; nothing outside report/
// includes this): the page's text helpers (text.cc), where a value comes
// from (coverage.cc), what every section reads (PageContext, built in
// report.cc), and the sections: the text ones (sections.cc), the
// inductance and flux figures (quantity_figure.cc), the operating-limit
// figures (limit_figures.cc). BuildReport (report.cc) puts them in order.
#ifndef FLUXCAL_REPORT_INTERNAL_H_
#define FLUXCAL_REPORT_INTERNAL_H_

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "plot/plot.h"
#include "report/format.h"
#include "report/report.h"
#include "tables/tables.h"

namespace fluxcal::report::internal {

// ---------------------------------------------------------------- text.cc

std::string H(const std::string& s);   // HTML text escape
std::string NowUtc();
std::vector<double> Linspace(double a, double b, int n);
// A JSON value as text: strings unquoted (their numbers rounded, they were
// written by another program), numbers rounded by `r`, "" when absent.
std::string ValueText(const nlohmann::json& v, Rounding r = Rounding{4, 0});
std::string JsonText(const nlohmann::json& j, const char* key, Rounding r = Rounding{4, 0});
// A relative residual (0.0123) as a percentage ("1.2 %").
std::string PercentText(const nlohmann::json& j, const char* key);
std::string Row(const std::string& k, const std::string& v);
// How a table axis or output named with its unit suffix is rounded.
Rounding RoundingOf(const std::string& name);
std::string UnitOf(const std::string& name);

// ------------------------------------------------------------ coverage.cc

// Where a value on the page comes from: the measured region, its mirror
// image (a model symmetric in iq: psi_d even, psi_q odd, so the unmeasured
// half is the measured one reflected), or the model's continuation beyond
// both. Every curve is drawn solid, dashed or dotted by it.
//
// The calibration keeps its region as |iq| and no flag says which half was
// measured; Coverage works that out. When calibrations and tables carry a
// "by symmetry" flag of their own, Source comes from it and
// MeasuredCoverage shrinks to reading it.
enum class Source { kMeasured = 0, kMirror = 1, kExtrapolated = 2 };

const char* DashOf(Source s);

struct Coverage {
  double id_lo = 0, id_hi = 0, iq_lo = 0, iq_hi = 0;   // the measured box, iq signed
  bool symmetric = true;                               // the model's family is mirror symmetric in iq
  std::string basis;                                   // how the box was found, said on the page
  bool InBox(double id, double iq) const {
    // The calibration's own margin (Calibration::InMeasuredRegion): 2 %.
    const double mi = 0.02 * (id_hi - id_lo + 1.0), mq = 0.02 * (iq_hi - iq_lo + 1.0);
    return id >= id_lo - mi && id <= id_hi + mi && iq >= iq_lo - mq && iq <= iq_hi + mq;
  }
  Source At(double id, double iq) const {
    if (InBox(id, iq)) return Source::kMeasured;
    if (symmetric && InBox(id, -iq)) return Source::kMirror;
    return Source::kExtrapolated;
  }
  bool MotoringMeasured() const { return iq_hi > 0.05 * std::max(std::abs(iq_lo), 1.0); }
  bool GeneratingMeasured() const { return iq_lo < -0.05 * std::max(std::abs(iq_hi), 1.0); }
  // What the unmeasured half is, in words.
  std::string OtherHalf() const {
    if (MotoringMeasured() && GeneratingMeasured()) return "Both halves measured";
    const char* missing = MotoringMeasured() ? "iq < 0 (generating)" : "iq > 0 (motoring)";
    return symmetric ? absl::StrCat(missing, ": by symmetry, the measured half mirrored (the model family is "
                                             "symmetric in iq)")
                     : absl::StrCat(missing, ": extrapolated (the model family is asymmetric in iq and nothing was "
                                             "measured there)");
  }
};

Coverage MeasuredCoverage(const fit::Calibration& cal, const fit::FitData* data);

// Draws y(x) as runs of equal source: solid, dashed (mirror) or dotted
// (extrapolated). Returns a bit per source drawn.
unsigned LineBySource(plot::Figure* f, const std::vector<double>& x, const std::vector<double>& y,
                      const std::vector<Source>& src, plot::Style st, std::string label);
// The legend's key to the line patterns, for the sources a figure drew.
void SourceKey(plot::Figure* f, unsigned drawn, const Coverage& cov);

// Where the differential inductance is not positive definite, on a grid
// over the measured region widened 1.5x, both signs of iq.
struct PdScan {
  int nx = 31, ny = 61, nodes = 0, bad = 0;
  int bad_by_source[3] = {0, 0, 0};
  double id_lo = 0, id_hi = 0, q_max = 0;
  std::vector<double> bad_id, bad_iq;
};

PdScan ScanPositiveDefinite(const fit::Calibration& cal, const Coverage& cov);
std::string PdText(const PdScan& s);

// ------------------------------------------------------------------ page

// The page's body as it grows, and its figures counted.
struct Page {
  std::string body;
  int figures = 0;
  void Figure(const plot::Figure& f, const std::string& caption) { Svg(f.Svg(), caption); }
  void Svg(const std::string& svg, const std::string& caption) {
    body += "<figure>" + svg + "<figcaption>" + caption + "</figcaption></figure>\n";
    ++figures;
  }
};

// What the sections read, worked out once from the inputs (report.cc):
// the limits by the export rule, the tables, the measured region, the
// base and ellipse speeds, the positive-definite scan.
struct PageContext {
  const ReportInputs* in = nullptr;
  const fit::Calibration* cal = nullptr;
  tables::MachineLimits lim;
  std::string i_max_source, udc_source;
  Coverage cov;
  // The voltage limit needs Udc and Rs; without either the page says so
  // (no_voltage) instead of drawing one at some default.
  bool voltage = false;
  std::string no_voltage;
  tables::TableSpec spec;   // the tables' common spec (serial, version, model, limit)
  std::map<std::string, tables::Table> tabs;   // mtpa, mtpv, and fw when there is a voltage limit
  std::string mtpv_note;
  bool mtpv_extrapolated = false;
  double base_rpm = 0, ell_rpm = 0, ell_we = 0;
  std::string ell_source, limits_warning;
  PdScan pd;
};

// The torque-speed envelope over the field-weakening table's speeds:
// motoring (tm) and generating (tg) limit torque and where each operating
// point lies. Empty without a voltage limit.
struct Envelope {
  std::vector<double> n, tm, tg;
  std::vector<Source> sm, sg;
};

// ------------------------------------------------------------ sections.cc

void IdentitySection(const PageContext& ctx, Page* page);
void FitSection(const PageContext& ctx, Page* page);
void TablesSection(const PageContext& ctx, Page* page);
void FleetSection(const PageContext& ctx, Page* page);
void DiagnosisSection(const PageContext& ctx, Page* page);

// ------------------------------------------------------ quantity_figure.cc

// Differential inductances and flux linkages over the current plane.
void SurfacesSection(const PageContext& ctx, Page* page);

// ------------------------------------------------------- limit_figures.cc

void CurrentPlaneSection(const PageContext& ctx, Page* page);
// Errors: INVALID_ARGUMENT when an envelope table cannot be built.
absl::StatusOr<Envelope> BuildEnvelope(const PageContext& ctx);
void EnvelopeSection(const PageContext& ctx, const Envelope& env, Page* page);
void FieldWeakeningSection(const PageContext& ctx, const Envelope& env, Page* page);

}  // namespace fluxcal::report::internal

#endif  // FLUXCAL_REPORT_INTERNAL_H_
