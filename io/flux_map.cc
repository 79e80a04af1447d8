#include "io/flux_map.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <system_error>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "io/csv.h"
#include "io/plausibility.h"

namespace fluxcal::io {
namespace {

enum Role { kId = 0, kIq, kPsiD, kPsiQ, kRoles };

// Spellings per role (matched case-insensitively), raw and symmetrised
// flux pairs.
const std::vector<std::string>& Spellings(Role r, FluxMapColumns columns) {
  static const std::vector<std::string> kIdNames = {"id_A", "id", "i_d", "i_d_A"};
  static const std::vector<std::string> kIqNames = {"iq_A", "iq", "i_q", "i_q_A"};
  static const std::vector<std::string> kPsiDRaw = {"psi_d_Vs", "psi_d_Wb", "psi_d_mVs", "psi_d_mWb",
                                                    "psi_d",    "psid",     "Fd"};
  static const std::vector<std::string> kPsiQRaw = {"psi_q_Vs", "psi_q_Wb", "psi_q_mVs", "psi_q_mWb",
                                                    "psi_q",    "psiq",     "Fq"};
  static const std::vector<std::string> kPsiDSym = {"psi_d_sym_Vs", "psi_d_sym_Wb", "psi_d_sym_mVs",
                                                    "psi_d_sym_mWb", "psi_d_sym"};
  static const std::vector<std::string> kPsiQSym = {"psi_q_sym_Vs", "psi_q_sym_Wb", "psi_q_sym_mVs",
                                                    "psi_q_sym_mWb", "psi_q_sym"};
  const bool sym = columns == FluxMapColumns::kSymmetrised;
  switch (r) {
    case kId: return kIdNames;
    case kIq: return kIqNames;
    case kPsiD: return sym ? kPsiDSym : kPsiDRaw;
    default: return sym ? kPsiQSym : kPsiQRaw;
  }
}

// The canonical name of a role in messages about a column that is absent.
const char* RoleName(Role r, FluxMapColumns columns) {
  const bool sym = columns == FluxMapColumns::kSymmetrised;
  switch (r) {
    case kId: return "id";
    case kIq: return "iq";
    case kPsiD: return sym ? "psi_d_sym" : "psi_d";
    default: return sym ? "psi_q_sym" : "psi_q";
  }
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// A cell or header echoed in a message: at most 40 bytes, escaped.
std::string Shorten(std::string_view s) {
  if (s.size() <= 40) return Printable(s);
  return absl::StrCat(Printable(s.substr(0, 37)), "...");
}

std::vector<std::string_view> SplitCells(std::string_view line) {
  std::vector<std::string_view> cells;
  size_t s = 0;
  while (true) {
    const size_t comma = line.find(',', s);
    cells.push_back(Trim(line.substr(s, comma == std::string_view::npos ? line.npos : comma - s)));
    if (comma == std::string_view::npos) break;
    s = comma + 1;
  }
  return cells;
}

// A current or flux value in a message: enough digits to tell nodes apart.
std::string Num(double x) { return absl::StrFormat("%.10g", x); }

struct Node {
  double psi_d_wb = 0, psi_q_wb = 0;
  size_t line = 0;
};

// ---- conventions and plausibility -------------------------------------------

// Where the messages about a whole map point: the file, its header line and
// the file's own column names.
struct Header {
  std::string path;
  size_t line = 1;
  std::string col[kRoles];
};

absl::Status MapError(const Header& h, size_t line, std::string_view field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(h.path, ":", line, ": field '", Shorten(field), "': ", what));
}

double UnitFactor(FluxUnit u) { return u == FluxUnit::kMWb || u == FluxUnit::kMVs ? 1e-3 : 1.0; }

// Peak value per unit of the file's |x| (flux_map.h, AmplitudeScaling).
double AmplitudeFactor(AmplitudeScaling a) {
  switch (a) {
    case AmplitudeScaling::kRms: return std::sqrt(2.0);
    case AmplitudeScaling::kPowerInvariant: return std::sqrt(2.0 / 3.0);
    default: return 1.0;
  }
}

// The unit a column name states by its suffix, if any.
std::optional<FluxUnit> HeaderUnit(std::string_view name) {
  const std::string n = absl::AsciiStrToLower(std::string(name));
  auto ends = [&](std::string_view suffix) {
    return n.size() > suffix.size() && n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  if (ends("_mwb")) return FluxUnit::kMWb;
  if (ends("_mvs")) return FluxUnit::kMVs;
  if (ends("_wb")) return FluxUnit::kWb;
  if (ends("_vs")) return FluxUnit::kVs;
  return std::nullopt;
}

// Direction of the flux at zero current, in the file's own axes.
enum class Dir { kNone, kPlusD, kMinusD, kPlusQ, kMinusQ, kOff };

// The flux at zero current is the magnet's alone: on an axis within
// kFluxMapAxisToleranceDeg (a rotor-angle offset of a few degrees in a
// measurement still names its axis; 10 degrees of offset would already
// misplace MTPA and is not a map to calibrate from), and "none" below
// kFluxMapNoMagnetFraction of the map's largest |psi| (a reluctance
// machine's remanence and a bench's offsets stay below 2 %; the weakest
// PM-assisted machines have 5..10 %).
Dir ZeroCurrentDirection(double pd, double pq, double scale, double* angle_deg) {
  *angle_deg = std::atan2(pq, pd) * 180.0 / 3.14159265358979323846;
  if (!(std::hypot(pd, pq) >= kFluxMapNoMagnetFraction * scale) || !(scale > 0)) return Dir::kNone;
  const double a = *angle_deg, tol = kFluxMapAxisToleranceDeg;
  if (std::abs(a) <= tol) return Dir::kPlusD;
  if (std::abs(a) >= 180.0 - tol) return Dir::kMinusD;
  if (std::abs(a - 90.0) <= tol) return Dir::kPlusQ;
  if (std::abs(a + 90.0) <= tol) return Dir::kMinusQ;
  return Dir::kOff;
}

// Even and odd parts in iq over the mirrored node pairs (id, iq), (id, -iq)
// with iq > 0: x(iq) = e + o with e = (x(iq) + x(-iq)) / 2, o = (x(iq) -
// x(-iq)) / 2, summed squares. A synchronous machine whose rotor is
// symmetric about its d axis has psi_d(id, -iq) = psi_d(id, iq) and
// psi_q(id, -iq) = -psi_q(id, iq) (reversing iq mirrors the field about d),
// so psi_d is even and psi_q odd; measured maps keep this to within their
// noise and cross-saturation hysteresis (the published PM-SyRM map: odd part
// of psi_d 0.5 % of its even part).
struct Symmetry {
  size_t pairs = 0;
  double d_even = 0, d_odd = 0, q_even = 0, q_odd = 0;
};

Symmetry MirrorSymmetry(const FluxMap& m) {
  Symmetry s;
  for (size_t j = 0; j < m.iq_a.size(); ++j) {
    if (!(m.iq_a[j] > 0)) continue;
    const auto it = std::lower_bound(m.iq_a.begin(), m.iq_a.end(), -m.iq_a[j]);
    if (it == m.iq_a.end() || *it != -m.iq_a[j]) continue;
    const size_t jm = static_cast<size_t>(it - m.iq_a.begin());
    for (size_t i = 0; i < m.id_a.size(); ++i) {
      const double dp = m.psi_d_wb[i][j], dm = m.psi_d_wb[i][jm], qp = m.psi_q_wb[i][j], qm = m.psi_q_wb[i][jm];
      s.d_even += 0.25 * (dp + dm) * (dp + dm);
      s.d_odd += 0.25 * (dp - dm) * (dp - dm);
      s.q_even += 0.25 * (qp + qm) * (qp + qm);
      s.q_odd += 0.25 * (qp - qm) * (qp - qm);
      ++s.pairs;
    }
  }
  return s;
}

// The map's own differential self-inductances by first differences,
// L_dd ~ (psi_d(id_{i+1}, iq) - psi_d(id_i, iq)) / (id_{i+1} - id_i) and
// L_qq likewise along iq; the median over all cells (robust to a few noisy
// nodes of a measured map). n = 0 when the axis has a single value.
struct DiffInductance {
  size_t n = 0;
  double median_h = 0;
};

DiffInductance MedianDifferential(const FluxMap& m, bool d_axis) {
  std::vector<double> l;
  const auto& axis = d_axis ? m.id_a : m.iq_a;
  for (size_t i = 0; i < m.id_a.size(); ++i) {
    for (size_t j = 0; j < m.iq_a.size(); ++j) {
      if (d_axis && i + 1 < m.id_a.size()) {
        l.push_back((m.psi_d_wb[i + 1][j] - m.psi_d_wb[i][j]) / (axis[i + 1] - axis[i]));
      } else if (!d_axis && j + 1 < m.iq_a.size()) {
        l.push_back((m.psi_q_wb[i][j + 1] - m.psi_q_wb[i][j]) / (axis[j + 1] - axis[j]));
      }
    }
  }
  DiffInductance r;
  r.n = l.size();
  if (l.empty()) return r;
  const size_t mid = l.size() / 2;
  std::nth_element(l.begin(), l.begin() + static_cast<std::ptrdiff_t>(mid), l.end());
  r.median_h = l[mid];
  if (l.size() % 2 == 0) {
    r.median_h = 0.5 * (r.median_h + *std::max_element(l.begin(), l.begin() + static_cast<std::ptrdiff_t>(mid)));
  }
  return r;
}

bool IsSyreName(std::string_view name) {
  const std::string n = absl::AsciiStrToLower(std::string(name));
  return n == "fd" || n == "fq";
}

// `raw` (the file's axes and numbers, a full grid; `nodes` the same with
// their lines) in fluxcal's convention, or the reason it cannot be one.
absl::StatusOr<FluxMap> Conform(const FluxMap& raw, const std::map<std::pair<double, double>, Node>& nodes,
                                const Header& h, const FluxMapConvention& conv) {
  AppliedFluxMapConvention ap;
  ap.current = conv.current;
  ap.flux = conv.flux;
  std::vector<std::string> notes;
  const auto& dcol = h.col[kPsiD];
  const auto& qcol = h.col[kPsiQ];

  // -- units and amplitude
  const auto hd = HeaderUnit(dcol), hq = HeaderUnit(qcol);
  if (conv.flux_unit == FluxUnit::kFromHeader) {
    if (hd && hq && UnitFactor(*hd) != UnitFactor(*hq)) {
      return MapError(h, h.line, qcol,
                      absl::StrCat("its unit differs from the psi_d column's ('", Shorten(dcol),
                                   "'): one map, one flux unit; give --units"));
    }
    ap.flux_unit = hd ? *hd : (hq ? *hq : FluxUnit::kWb);
    ap.flux_unit_source = hd || hq ? "header" : "assumed";
  } else {
    ap.flux_unit = conv.flux_unit;
    ap.flux_unit_source = "flag";
    const auto stated = hd ? hd : hq;
    if (stated && UnitFactor(*stated) != UnitFactor(conv.flux_unit)) {
      notes.push_back(absl::StrCat("--units ", Name(conv.flux_unit), " overrides the header's '",
                                   Shorten(hd ? dcol : qcol), "'"));
    }
  }
  ap.current_factor = AmplitudeFactor(conv.current);
  ap.flux_factor = AmplitudeFactor(conv.flux) * UnitFactor(ap.flux_unit);
  const double cf = ap.current_factor, ff = ap.flux_factor;
  const std::string unit_read = absl::StrCat(Name(ap.flux_unit), ap.flux != AmplitudeScaling::kPeak
                                                                     ? absl::StrCat(", ", Name(ap.flux)) : "");

  // -- magnitudes: the service's limits (io/plausibility.h)
  double scale = 0;   // largest |psi| as written
  const std::pair<const std::pair<double, double>, Node>* biggest = nullptr;
  for (const auto& kv : nodes) {
    const auto& [key, node] = kv;
    for (int r : {kId, kIq}) {
      const double v = (r == kId ? key.first : key.second) * cf;
      if (std::abs(v) > kMaxAbsCurrentA) {
        return MapError(h, node.line, h.col[r],
                        absl::StrFormat("current %.6g A (read as %s) is beyond the +-%g kA of a plausible machine: "
                                        "are the currents in mA? (fluxcal reads A)",
                                        v, Name(ap.current), kMaxAbsCurrentA / 1e3));
      }
    }
    const double m = std::hypot(node.psi_d_wb, node.psi_q_wb);
    if (biggest == nullptr || m > scale) {
      scale = m;
      biggest = &kv;
    }
  }
  const auto zero = nodes.find({0.0, 0.0});
  const bool has_zero = zero != nodes.end();
  const std::string unit_hint = UnitFactor(ap.flux_unit) == 1.0
                                    ? "is the flux in mWb? give --units mWb"
                                    : absl::StrCat("is the unit right? (read in ", Name(ap.flux_unit), ")");
  if (has_zero) {
    const double pm = std::hypot(zero->second.psi_d_wb, zero->second.psi_q_wb) * ff;
    if (pm > kMaxFluxLinkageWb) {
      const bool d_larger = std::abs(zero->second.psi_d_wb) >= std::abs(zero->second.psi_q_wb);
      return MapError(h, zero->second.line, d_larger ? dcol : qcol,
                      absl::StrFormat("psi_pm %.4g Wb (the flux at zero current, read in %s) is above the %g Wb of a "
                                      "plausible machine: %s",
                                      pm, unit_read, kMaxFluxLinkageWb, unit_hint));
    }
  }
  if (scale * ff > kMaxFluxLinkageWb) {
    const auto& [key, node] = *biggest;
    return MapError(h, node.line, std::abs(node.psi_d_wb) >= std::abs(node.psi_q_wb) ? dcol : qcol,
                    absl::StrFormat("|psi| %.4g Wb at id = %s A, iq = %s A (read in %s) is above the %g Wb of a "
                                    "plausible machine: %s",
                                    scale * ff, Num(key.first), Num(key.second), unit_read, kMaxFluxLinkageWb,
                                    unit_hint));
  }

  // -- axes: the magnet flux at zero current
  const bool syre_names = IsSyreName(dcol) || IsSyreName(qcol);
  const std::string syre_hint =
      syre_names ? absl::StrCat(" (the header's '", Shorten(dcol), "', '", Shorten(qcol),
                                "' are SyR-e's names: --convention syre if it is a SyR-e export)")
                 : "";
  std::string at_zero;
  Dir dir = Dir::kNone;
  double angle = 0;
  if (has_zero) {
    at_zero = absl::StrFormat("%s = %.4g Wb, %s = %.4g Wb at id = iq = 0", Shorten(dcol),
                              zero->second.psi_d_wb * ff, Shorten(qcol), zero->second.psi_q_wb * ff);
    dir = ZeroCurrentDirection(zero->second.psi_d_wb, zero->second.psi_q_wb, scale, &angle);
  }
  const size_t zline = has_zero ? zero->second.line : h.line;
  const bool given = conv.axes != FluxMapAxes::kAuto;
  const bool syre_given = conv.axes == FluxMapAxes::kSyre;
  ap.axes = conv.axes;
  if (!has_zero) {
    if (!given) {
      return MapError(h, h.line, dcol,
                      absl::StrCat("no node at id = iq = 0: the magnet axis cannot be detected from the map; give "
                                   "--convention fluxcal|motulator|syre",
                                   syre_hint));
    }
    notes.push_back("no node at zero current: axes as given, not checked");
  } else {
    switch (dir) {
      case Dir::kNone:
        if (!given) {
          return MapError(h, zline, dcol,
                          absl::StrFormat("no magnet flux at zero current (%s; under %g %% of the map's largest |psi| "
                                          "%.4g Wb): the axes of a reluctance machine's map cannot be told from it; "
                                          "give --convention fluxcal|motulator|syre%s",
                                          at_zero, 100 * kFluxMapNoMagnetFraction, scale * ff, syre_hint));
        }
        notes.push_back(absl::StrCat("no magnet flux at zero current (", at_zero, "): axes as given"));
        break;
      case Dir::kPlusD:
        if (syre_given) {
          return MapError(h, zline, dcol,
                          absl::StrCat("--convention syre: SyR-e's axes put the magnet on -q, but this map has it "
                                       "on +d (", at_zero, "): fluxcal's or motulator's axes; give --convention "
                                       "fluxcal (or auto)"));
        }
        if (!given) ap.axes = FluxMapAxes::kFluxcal;
        notes.push_back(absl::StrCat("magnet flux on +d (", at_zero, ", line ", zline, ")",
                                     syre_names ? "; the header uses SyR-e's names, but the magnet says fluxcal's axes"
                                                : ""));
        break;
      case Dir::kMinusQ:
        if (given && !syre_given) {
          return MapError(h, zline, qcol,
                          absl::StrCat("the magnet lies on the -q axis (", at_zero,
                                       "): a SyR-e map (d the high-permeance axis, the magnet on -q)? give "
                                       "--convention syre (or auto)"));
        }
        ap.axes = FluxMapAxes::kSyre;
        notes.push_back(absl::StrCat("magnet flux on -q (", at_zero, ", line ", zline, ")"));
        break;
      case Dir::kPlusQ: {
        const Symmetry s = MirrorSymmetry(raw);
        const bool sym_says = s.pairs >= 3 && s.d_odd > s.d_even && s.q_even > s.q_odd;
        return MapError(
            h, zline, qcol,
            absl::StrCat("the psi_d and psi_q columns look exchanged: the magnet flux lies on +q (", at_zero, ")",
                         sym_says ? absl::StrFormat(", and '%s' is odd in iq while '%s' is even over %zu mirrored "
                                                    "node pairs",
                                                    Shorten(dcol), Shorten(qcol), s.pairs)
                                  : "",
                         "; fluxcal's and motulator's axes put it on +d, SyR-e's on -q: exchange the two flux "
                         "columns' names"));
      }
      case Dir::kMinusD:
        return MapError(h, zline, dcol,
                        absl::StrCat("the magnet lies on the -d axis (", at_zero,
                                     "): the d axis reversed (psi_d and id negated), or a SyR-e map with its Fd and "
                                     "Fq exchanged (SyR-e puts the magnet on -q)? fluxcal's and motulator's axes put "
                                     "it on +d"));
      case Dir::kOff:
        return MapError(h, zline, dcol,
                        absl::StrFormat("the flux at zero current (%s) points at %.1f deg, not along an axis (within "
                                        "%g deg): the map's dq frame is not aligned with the rotor's magnet (an angle "
                                        "offset in the measurement?)",
                                        at_zero, angle, kFluxMapAxisToleranceDeg));
    }
  }
  ap.axes_detected = !given;

  // -- into fluxcal's axes and scaling
  const bool syre = ap.axes == FluxMapAxes::kSyre;
  FluxMap out;
  out.source = raw.source;
  const size_t ni = raw.id_a.size(), nq = raw.iq_a.size();
  if (!syre) {
    for (double v : raw.id_a) out.id_a.push_back(v * cf + 0.0);
    for (double v : raw.iq_a) out.iq_a.push_back(v * cf + 0.0);
    out.psi_d_wb = raw.psi_d_wb;
    out.psi_q_wb = raw.psi_q_wb;
    for (auto* g : {&out.psi_d_wb, &out.psi_q_wb}) {
      for (auto& row : *g) {
        for (double& v : row) v *= ff;
      }
    }
  } else {
    // id = -Iq, iq = Id, psi_d = -Fq, psi_q = Fd (flux_map.h, kSyre): the
    // new id axis is the old iq axis negated and reversed.
    for (size_t k = 0; k < nq; ++k) out.id_a.push_back(-raw.iq_a[nq - 1 - k] * cf + 0.0);
    for (double v : raw.id_a) out.iq_a.push_back(v * cf + 0.0);
    out.psi_d_wb.assign(nq, std::vector<double>(ni));
    out.psi_q_wb.assign(nq, std::vector<double>(ni));
    for (size_t i = 0; i < nq; ++i) {
      for (size_t j = 0; j < ni; ++j) {
        out.psi_d_wb[i][j] = -raw.psi_q_wb[j][nq - 1 - i] * ff + 0.0;
        out.psi_q_wb[i][j] = raw.psi_d_wb[j][nq - 1 - i] * ff + 0.0;
      }
    }
  }
  // The file's column behind fluxcal's psi_d and psi_q, for messages.
  const std::string& d_src = syre ? qcol : dcol;
  const std::string& q_src = syre ? dcol : qcol;
  const std::string frame = syre ? " (in fluxcal's axes, after the SyR-e conversion)" : "";

  // -- symmetry: psi_d even in iq, psi_q odd
  if (const Symmetry s = MirrorSymmetry(out); s.pairs >= 3) {
    const bool bad_d = s.d_odd > s.d_even, bad_q = s.q_even > s.q_odd;
    const std::string law = "a synchronous machine's psi_d(id, -iq) = psi_d(id, iq) and psi_q(id, -iq) = "
                            "-psi_q(id, iq)";
    if (bad_d && bad_q) {
      return MapError(h, h.line, d_src,
                      absl::StrFormat("the psi_d and psi_q columns look exchanged: psi_d is odd in iq and psi_q "
                                      "even over %zu mirrored node pairs%s (%s): exchange the two flux columns' names",
                                      s.pairs, frame, law));
    }
    if (bad_d || bad_q) {
      const bool d = bad_d;
      return MapError(h, h.line, d ? d_src : q_src,
                      absl::StrFormat("psi_%s is mostly %s in iq (RMS of its %s part %.3g Wb, of its %s part %.3g Wb "
                                      "over %zu mirrored node pairs%s), against %s: are the axes or a column's sign "
                                      "wrong? (--convention)",
                                      d ? "d" : "q", d ? "odd" : "even", d ? "odd" : "even",
                                      std::sqrt((d ? s.d_odd : s.q_even) / static_cast<double>(s.pairs)),
                                      d ? "even" : "odd",
                                      std::sqrt((d ? s.d_even : s.q_odd) / static_cast<double>(s.pairs)), s.pairs,
                                      frame, law));
    }
  }

  // -- the map's own differential inductances
  for (bool d_axis : {true, false}) {
    const DiffInductance L = MedianDifferential(out, d_axis);
    if (L.n == 0) continue;
    if (L.median_h >= kMinInductanceH && L.median_h < kMaxInductanceH) continue;
    const char* x = d_axis ? "d" : "q";
    std::string cause;
    if (L.median_h >= kMaxInductanceH) {
      cause = UnitFactor(ap.flux_unit) == 1.0 ? "is the flux in mWb (give --units mWb) or the current in kA?"
                                              : "is the current in kA?";
    } else if (L.median_h < 0) {
      cause = absl::StrFormat("psi_%s falls as i%s rises: is psi_%s or i%s negated (the %s axis reversed)?", x, x, x,
                              x, x);
    } else {
      cause = "the flux barely changes with the current: a constant or copied column, the current in mA, or "
              "--units mWb on a map in Wb?";
    }
    return MapError(h, h.line, d_axis ? d_src : q_src,
                    absl::StrFormat("differential inductance L_%s%s = dpsi_%s/di%s %.4g H (median of the map's %zu "
                                    "differences%s) is outside the plausible [%g, %g) H: %s",
                                    x, x, x, x, L.median_h, L.n, frame, kMinInductanceH, kMaxInductanceH, cause));
  }

  ap.detail = absl::StrJoin(notes, "; ");
  out.convention = ap;
  return out;
}

}  // namespace

const char* Name(FluxMapAxes axes) {
  switch (axes) {
    case FluxMapAxes::kAuto: return "auto";
    case FluxMapAxes::kFluxcal: return "fluxcal";
    case FluxMapAxes::kMotulator: return "motulator";
    default: return "syre";
  }
}

const char* Name(AmplitudeScaling scaling) {
  switch (scaling) {
    case AmplitudeScaling::kPeak: return "peak";
    case AmplitudeScaling::kRms: return "rms";
    default: return "power-invariant";
  }
}

const char* Name(FluxUnit unit) {
  switch (unit) {
    case FluxUnit::kFromHeader: return "header";
    case FluxUnit::kWb: return "Wb";
    case FluxUnit::kVs: return "Vs";
    case FluxUnit::kMWb: return "mWb";
    default: return "mVs";
  }
}

std::optional<FluxMapAxes> FluxMapAxesFromName(std::string_view name) {
  for (auto a : {FluxMapAxes::kAuto, FluxMapAxes::kFluxcal, FluxMapAxes::kMotulator, FluxMapAxes::kSyre}) {
    if (name == Name(a)) return a;
  }
  return std::nullopt;
}

std::optional<AmplitudeScaling> AmplitudeScalingFromName(std::string_view name) {
  for (auto a : {AmplitudeScaling::kPeak, AmplitudeScaling::kRms, AmplitudeScaling::kPowerInvariant}) {
    if (name == Name(a)) return a;
  }
  return std::nullopt;
}

std::optional<FluxUnit> FluxUnitFromName(std::string_view name) {
  for (auto u : {FluxUnit::kFromHeader, FluxUnit::kWb, FluxUnit::kVs, FluxUnit::kMWb, FluxUnit::kMVs}) {
    if (name == Name(u)) return u;
  }
  return std::nullopt;
}

std::string AppliedFluxMapConvention::Describe() const {
  std::string s = absl::StrCat("axes ", Name(axes), " (", axes_detected ? "detected" : "given",
                               detail.empty() ? "" : ": ", detail, ")");
  if (axes == FluxMapAxes::kSyre) absl::StrAppend(&s, ", converted: id = -Iq, iq = Id, psi_d = -Fq, psi_q = Fd");
  absl::StrAppend(&s, "; currents ", Name(current));
  if (current_factor != 1.0) absl::StrAppendFormat(&s, " (x %.6g)", current_factor);
  absl::StrAppend(&s, "; flux ", Name(flux), " in ", Name(flux_unit), " (", flux_unit_source, ")");
  if (flux_factor != 1.0) absl::StrAppendFormat(&s, " (x %.6g)", flux_factor);
  return s;
}


std::vector<FluxMapPoint> FluxMap::Points() const {
  std::vector<FluxMapPoint> out;
  out.reserve(size());
  for (size_t i = 0; i < id_a.size(); ++i) {
    for (size_t j = 0; j < iq_a.size(); ++j) {
      out.push_back({id_a[i], iq_a[j], psi_d_wb[i][j], psi_q_wb[i][j]});
    }
  }
  return out;
}

absl::StatusOr<FluxMap> ParseFluxMapCsv(std::string_view text, const std::string& path,
                                        const FluxMapReadOptions& options) {
  auto error = [&](size_t line, std::string_view field, const std::string& what) {
    return absl::InvalidArgumentError(absl::StrCat(path, ":", line, ": field '", Shorten(field), "': ", what));
  };
  if (text.size() > kMaxFluxMapBytes) {
    return error(1, "(file)", absl::StrCat("file is ", text.size(), " bytes, more than the ",
                                           kMaxFluxMapBytes >> 20, " MiB a flux map may have"));
  }
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);   // UTF-8 BOM (spreadsheet exports)

  size_t pos = 0, line_no = 0;
  int col[kRoles] = {-1, -1, -1, -1};
  std::vector<std::string> header;
  bool header_seen = false;
  size_t header_line = 1;
  std::map<std::pair<double, double>, Node> nodes;
  size_t rows = 0;
  while (pos < text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    const std::string_view line = Trim(text.substr(pos, eol - pos));
    pos = eol + 1;
    ++line_no;
    if (!header_seen) {
      if (line.empty() || line.front() == '#') continue;   // preamble
      header_seen = true;
      header_line = line_no;
      for (auto name : SplitCells(line)) {
        if (name.size() >= 2 && name.front() == '"' && name.back() == '"') name = name.substr(1, name.size() - 2);
        header.emplace_back(name);
      }
      for (int r = 0; r < kRoles; ++r) {
        const auto& names = Spellings(static_cast<Role>(r), options.columns);
        for (size_t c = 0; c < header.size(); ++c) {
          const std::string lower = absl::AsciiStrToLower(header[c]);
          if (std::none_of(names.begin(), names.end(),
                           [&](const std::string& n) { return absl::AsciiStrToLower(n) == lower; })) {
            continue;
          }
          if (col[r] >= 0) {
            return error(line_no, header[c],
                         absl::StrCat("ambiguous: columns ", col[r] + 1, " ('", Shorten(header[col[r]]), "') and ",
                                      c + 1, " both name ", RoleName(static_cast<Role>(r), options.columns)));
          }
          col[r] = static_cast<int>(c);
        }
      }
      for (int r = 0; r < kRoles; ++r) {
        if (col[r] >= 0) continue;
        std::vector<std::string> shown;
        for (size_t c = 0; c < header.size() && c < 12; ++c) shown.push_back(Shorten(header[c]));
        if (header.size() > 12) shown.push_back(absl::StrCat("... (", header.size(), " columns)"));
        std::string what = absl::StrCat("missing column (accepted, any case: ",
                                        absl::StrJoin(Spellings(static_cast<Role>(r), options.columns), ", "),
                                        "; header has ", absl::StrJoin(shown, ", "), ")");
        if (header.size() == 1 && (line.find(';') != line.npos || line.find('\t') != line.npos)) {
          absl::StrAppend(&what, "; expected comma-separated values");
        }
        return error(line_no, RoleName(static_cast<Role>(r), options.columns), what);
      }
      continue;
    }
    if (line.empty()) {
      // Only trailing empty lines are tolerated.
      if (text.substr(std::min(pos, text.size())).find_first_not_of("\r\n \t") == std::string_view::npos) break;
      return error(line_no, header[col[kId]], "empty line");
    }
    if (++rows > kMaxFluxMapRows) {
      return error(line_no, header[col[kId]],
                   absl::StrCat("more than ", kMaxFluxMapRows, " rows; a flux map is a grid of at most 1000 x 1000"));
    }
    const auto cells = SplitCells(line);
    if (cells.size() != header.size()) {
      const size_t c = std::min(cells.size(), header.size() - 1);
      return error(line_no, header[c],
                   absl::StrCat(cells.size() < header.size() ? "missing cell" : "too many cells", " (row has ",
                                cells.size(), ", header ", header.size(), ")"));
    }
    double v[kRoles];
    for (int r = 0; r < kRoles; ++r) {
      const std::string_view cell = cells[col[r]];
      const std::string& field = header[col[r]];
      if (cell.empty()) return error(line_no, field, "empty cell");
      const char* b = cell.data();
      const char* e = cell.data() + cell.size();
      if (*b == '+') ++b;   // from_chars rejects a leading '+'
      auto [ptr, ec] = std::from_chars(b, e, v[r]);
      if (ec == std::errc::result_out_of_range) {
        return error(line_no, field, absl::StrCat("number out of range, got '", Shorten(cell), "'"));
      }
      if (ec != std::errc() || ptr != e) {
        return error(line_no, field, absl::StrCat("expected a number, got '", Shorten(cell), "'"));
      }
      if (!std::isfinite(v[r])) {
        return error(line_no, field, absl::StrCat("expected a finite number, got '", Shorten(cell), "'"));
      }
    }
    // -0 + 0 = +0: "-0" and "0" are one axis value.
    const std::pair<double, double> key{v[kId] + 0.0, v[kIq] + 0.0};
    auto [it, inserted] = nodes.emplace(key, Node{v[kPsiD], v[kPsiQ], line_no});
    if (!inserted) {
      return error(line_no, header[col[kIq]],
                   absl::StrCat("duplicate node (id = ", Num(key.first), " A, iq = ", Num(key.second),
                                " A), first on line ", it->second.line));
    }
  }
  if (!header_seen) return error(1, "id", "empty file, no header");
  if (nodes.empty()) return error(line_no, header[col[kId]], "no data rows after the header");

  FluxMap map;
  map.source = path;
  std::set<double> ids, iqs;
  for (const auto& [key, node] : nodes) {
    ids.insert(key.first);
    iqs.insert(key.second);
  }
  map.id_a.assign(ids.begin(), ids.end());
  map.iq_a.assign(iqs.begin(), iqs.end());
  const size_t ni = map.id_a.size(), nq = map.iq_a.size();
  map.psi_d_wb.assign(ni, std::vector<double>(nq));
  map.psi_q_wb.assign(ni, std::vector<double>(nq));
  for (size_t i = 0; i < ni; ++i) {
    for (size_t j = 0; j < nq; ++j) {
      auto it = nodes.find({map.id_a[i], map.iq_a[j]});
      if (it != nodes.end()) {
        map.psi_d_wb[i][j] = it->second.psi_d_wb;
        map.psi_q_wb[i][j] = it->second.psi_q_wb;
        continue;
      }
      // Point at the nearest node of the same id row: where a map written
      // id-major lost its line. Every id value has at least one node.
      size_t best_line = 0;
      double best_iq = 0;
      for (size_t d = 1; d < nq && best_line == 0; ++d) {
        for (const size_t jj : {j - d, j + d}) {   // j - d wraps to a huge index when d > j
          if (jj >= nq) continue;
          if (auto nb = nodes.find({map.id_a[i], map.iq_a[jj]}); nb != nodes.end()) {
            best_line = nb->second.line;
            best_iq = map.iq_a[jj];
            break;
          }
        }
      }
      return error(best_line, header[col[kIq]],
                   absl::StrCat("missing node (id = ", Num(map.id_a[i]), " A, iq = ", Num(map.iq_a[j]),
                                " A): the map is not a full grid (", ni, " id values x ", nq, " iq values need ",
                                ni * nq, " nodes, the file has ", nodes.size(),
                                "); nearest node of this id row: iq = ", Num(best_iq), " A on line ", best_line));
    }
  }
  Header h;
  h.path = path;
  h.line = header_line;
  for (int r = 0; r < kRoles; ++r) h.col[r] = header[col[r]];
  return Conform(map, nodes, h, options.convention);
}

absl::StatusOr<FluxMap> ReadFluxMapCsv(const std::string& path, const FluxMapReadOptions& options) {
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(path, ec);
  if (!ec && bytes > kMaxFluxMapBytes) {
    return absl::InvalidArgumentError(absl::StrCat(path, ":1: field '(file)': file is ", bytes,
                                                   " bytes, more than the ", kMaxFluxMapBytes >> 20,
                                                   " MiB a flux map may have"));
  }
  auto text = ReadFileToString(path);
  if (!text.ok()) return text.status();
  return ParseFluxMapCsv(*text, path, options);
}

absl::Status ValidateFluxMap(const FluxMap& map) {
  auto axis_ok = [](const std::vector<double>& a) {
    if (a.empty()) return false;
    for (size_t k = 0; k < a.size(); ++k) {
      if (!std::isfinite(a[k]) || (k > 0 && !(a[k] > a[k - 1]))) return false;
    }
    return true;
  };
  if (!axis_ok(map.id_a)) return absl::InvalidArgumentError("field 'id_a': axis must be finite, strictly increasing, non-empty");
  if (!axis_ok(map.iq_a)) return absl::InvalidArgumentError("field 'iq_a': axis must be finite, strictly increasing, non-empty");
  for (const auto* grid : {&map.psi_d_wb, &map.psi_q_wb}) {
    const char* name = grid == &map.psi_d_wb ? "psi_d_wb" : "psi_q_wb";
    if (grid->size() != map.id_a.size()) {
      return absl::InvalidArgumentError(absl::StrCat("field '", name, "': ", grid->size(), " rows for ",
                                                     map.id_a.size(), " id values"));
    }
    for (size_t i = 0; i < grid->size(); ++i) {
      if ((*grid)[i].size() != map.iq_a.size()) {
        return absl::InvalidArgumentError(absl::StrCat("field '", name, "[", i, "]': ", (*grid)[i].size(),
                                                       " values for ", map.iq_a.size(), " iq values"));
      }
      for (size_t j = 0; j < (*grid)[i].size(); ++j) {
        if (!std::isfinite((*grid)[i][j])) {
          return absl::InvalidArgumentError(absl::StrCat("field '", name, "[", i, "][", j, "]': not finite"));
        }
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::string> FluxMapCsv(const FluxMap& map) {
  if (auto st = ValidateFluxMap(map); !st.ok()) return st;
  std::string out = "id_A,iq_A,psi_d_Vs,psi_q_Vs\n";
  out.reserve(out.size() + map.size() * 96);
  // %.17g: 17 significant digits identify every double uniquely (IEEE 754
  // binary64, DBL_DECIMAL_DIG), so the text reads back bit for bit.
  for (const auto& p : map.Points()) {
    absl::StrAppendFormat(&out, "%.17g,%.17g,%.17g,%.17g\n", p.id_a, p.iq_a, p.psi_d_wb, p.psi_q_wb);
  }
  return out;
}

absl::Status WriteFluxMapCsv(const std::string& path, const FluxMap& map) {
  auto text = FluxMapCsv(map);
  if (!text.ok()) return text.status();
  return WriteFileAtomically(path, *text);
}

}  // namespace fluxcal::io
