// A parsed flux map put into fluxcal's convention, or refused with the
// reason: the flux unit and amplitude scaling, the service's plausible
// magnitudes (io/plausibility.h), the axes told from the magnet flux at
// zero current (SyR-e's converted), psi_d even and psi_q odd in iq, and
// the map's own differential inductances in a plausible range.
#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "io/flux_map.h"
#include "io/flux_map_internal.h"
#include "io/plausibility.h"

namespace fluxcal::io::internal {
namespace {

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

// The flux unit (from the header or the flag) and the amplitude scaling:
// the factors into A and Wb peak.
absl::Status ReadUnits(const Header& h, const FluxMapConvention& conv, AppliedFluxMapConvention* out,
                       std::vector<std::string>* notes) {
  AppliedFluxMapConvention& ap = *out;
  const auto& dcol = h.col[kPsiD];
  const auto& qcol = h.col[kPsiQ];
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
      notes->push_back(absl::StrCat("--units ", Name(conv.flux_unit), " overrides the header's '",
                                   Shorten(hd ? dcol : qcol), "'"));
    }
  }
  ap.current_factor = AmplitudeFactor(conv.current);
  ap.flux_factor = AmplitudeFactor(conv.flux) * UnitFactor(ap.flux_unit);
  return absl::OkStatus();
}

// Magnitudes: the service's limits (io/plausibility.h). Returns the
// largest |psi| as written.
absl::StatusOr<double> CheckMagnitudes(const Nodes& nodes, const Header& h, const AppliedFluxMapConvention& ap) {
  const auto& dcol = h.col[kPsiD];
  const auto& qcol = h.col[kPsiQ];
  const double cf = ap.current_factor, ff = ap.flux_factor;
  const std::string unit_read = absl::StrCat(Name(ap.flux_unit), ap.flux != AmplitudeScaling::kPeak
                                                                     ? absl::StrCat(", ", Name(ap.flux)) : "");
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
  return scale;
}

// The axes: told from the magnet flux at zero current (or as given, where
// it cannot tell), refused where the map's axes are none of the known ones.
absl::Status DetectAxes(const FluxMap& raw, const Nodes& nodes, const Header& h, const FluxMapConvention& conv,
                        double scale, AppliedFluxMapConvention* out, std::vector<std::string>* notes) {
  AppliedFluxMapConvention& ap = *out;
  const auto& dcol = h.col[kPsiD];
  const auto& qcol = h.col[kPsiQ];
  const double ff = ap.flux_factor;
  const auto zero = nodes.find({0.0, 0.0});
  const bool has_zero = zero != nodes.end();
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
    notes->push_back("no node at zero current: axes as given, not checked");
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
        notes->push_back(absl::StrCat("no magnet flux at zero current (", at_zero, "): axes as given"));
        break;
      case Dir::kPlusD:
        if (syre_given) {
          return MapError(h, zline, dcol,
                          absl::StrCat("--convention syre: SyR-e's axes put the magnet on -q, but this map has it "
                                       "on +d (", at_zero, "): fluxcal's or motulator's axes; give --convention "
                                       "fluxcal (or auto)"));
        }
        if (!given) ap.axes = FluxMapAxes::kFluxcal;
        notes->push_back(absl::StrCat("magnet flux on +d (", at_zero, ", line ", zline, ")",
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
        notes->push_back(absl::StrCat("magnet flux on -q (", at_zero, ", line ", zline, ")"));
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
  return absl::OkStatus();
}

// Into fluxcal's axes and scaling.
FluxMap ToFluxcalAxes(const FluxMap& raw, const AppliedFluxMapConvention& ap) {
  const double cf = ap.current_factor, ff = ap.flux_factor;
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
  return out;
}

// The file's column behind fluxcal's psi_d and psi_q, for messages.
struct Sources {
  std::string d_src, q_src, frame;
};

Sources SourcesOf(const Header& h, const AppliedFluxMapConvention& ap) {
  const bool syre = ap.axes == FluxMapAxes::kSyre;
  const auto& dcol = h.col[kPsiD];
  const auto& qcol = h.col[kPsiQ];
  return {syre ? qcol : dcol, syre ? dcol : qcol,
          syre ? " (in fluxcal's axes, after the SyR-e conversion)" : ""};
}

// Symmetry: psi_d even in iq, psi_q odd.
absl::Status CheckSymmetry(const FluxMap& out, const Header& h, const Sources& src) {
  const std::string& d_src = src.d_src;
  const std::string& q_src = src.q_src;
  const std::string& frame = src.frame;
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
  return absl::OkStatus();
}

// The map's own differential inductances, within the plausible range.
absl::Status CheckInductances(const FluxMap& out, const Header& h, const AppliedFluxMapConvention& ap,
                              const Sources& src) {
  const std::string& d_src = src.d_src;
  const std::string& q_src = src.q_src;
  const std::string& frame = src.frame;
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
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<FluxMap> Conform(const FluxMap& raw, const Nodes& nodes, const Header& h,
                                const FluxMapConvention& conv) {
  AppliedFluxMapConvention ap;
  ap.current = conv.current;
  ap.flux = conv.flux;
  std::vector<std::string> notes;
  if (absl::Status s = ReadUnits(h, conv, &ap, &notes); !s.ok()) return s;
  const auto scale = CheckMagnitudes(nodes, h, ap);
  if (!scale.ok()) return scale.status();
  if (absl::Status s = DetectAxes(raw, nodes, h, conv, *scale, &ap, &notes); !s.ok()) return s;
  FluxMap out = ToFluxcalAxes(raw, ap);
  const Sources src = SourcesOf(h, ap);
  if (absl::Status s = CheckSymmetry(out, h, src); !s.ok()) return s;
  if (absl::Status s = CheckInductances(out, h, ap, src); !s.ok()) return s;
  ap.detail = absl::StrJoin(notes, "; ");
  out.convention = ap;
  return out;
}

}  // namespace fluxcal::io::internal
