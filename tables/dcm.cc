// The DCM export format: DAMOS DCM 2.0 (docs/tables.md).
#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_replace.h"
#include "tables/internal_formats.h"
#include "tables/tables.h"

namespace fluxcal::tables::internal {

std::string Dcm(const Table& t) {
  // DAMOS DCM 2.0 (KONSERVIERUNG_FORMAT 2.0): FESTWERT (scalar), KENNLINIE
  // (curve) and KENNFELD (map) blocks, 6 values a line; text metadata as
  // '*' comments (DCM has no text scalar every tool accepts).
  std::string s = absl::StrFormat("* fluxcal %s table\n", TableTitle(t));
  for (const auto& [k, v] : TextFields(t)) s += absl::StrCat("* ", k, ": ", OneLine(v), "\n");
  s += absl::StrCat("* axis_order: ", AxisOrder(t), "\n");
  s += absl::StrCat("* payload_crc32: ", Crc(t), ", payload_sha256: ", t.sha256,
                    " (over the values, fluxcal docs/tables.md; not over this file)\n\nKONSERVIERUNG_FORMAT 2.0\n\n");
  auto line = [&](const std::string& key, const std::vector<double>& v) {
    for (size_t k = 0; k < v.size(); k += 6) {
      s += absl::StrCat("   ", key);
      for (size_t m = k; m < std::min(v.size(), k + 6); ++m) s += absl::StrCat(" ", Num(v[m]));
      s += "\n";
    }
  };
  for (const auto& sc : Scalars(t)) {
    s += absl::StrFormat("FESTWERT %s\n   LANGNAME \"%s\"\n   EINHEIT_W \"%s\"\n   WERT %s\nEND\n\n", Label(t, sc.name),
                         absl::StrReplaceAll(OneLine(sc.description), {{"\"", "'"}}), sc.unit, Num(sc.value));
  }
  const bool map = t.axes.size() > 1;
  const size_t n0 = t.axes[0].values.size(), n1 = map ? t.axes[1].values.size() : 1;
  auto block = [&](const std::string& name, const std::string& unit, const std::vector<double>& vals) {
    if (!map) {
      s += absl::StrFormat("KENNLINIE %s %d\n   LANGNAME \"%s over %s\"\n   EINHEIT_X \"%s\"\n   EINHEIT_W \"%s\"\n",
                           Label(t, name), n0, name, t.axes[0].name, UnitOf(t.axes[0].name), unit);
      line("ST/X", t.axes[0].values);
      line("WERT", vals);
    } else {
      // KENNFELD name nx ny: ST/X the X axis (first axis), then per Y value
      // (second axis) one ST/Y line and the WERT values over X.
      s += absl::StrFormat("KENNFELD %s %d %d\n   LANGNAME \"%s over %s x %s\"\n   EINHEIT_X \"%s\"\n   EINHEIT_Y \"%s\"\n   EINHEIT_W \"%s\"\n",
                           Label(t, name), n0, n1, name, t.axes[0].name, t.axes[1].name, UnitOf(t.axes[0].name),
                           UnitOf(t.axes[1].name), unit);
      line("ST/X", t.axes[0].values);
      for (size_t j = 0; j < n1; ++j) {
        s += absl::StrCat("   ST/Y ", Num(t.axes[1].values[j]), "\n");
        std::vector<double> row(n0);
        for (size_t i = 0; i < n0; ++i) row[i] = vals[i * n1 + j];
        line("WERT", row);
      }
    }
    s += "END\n\n";
  };
  for (const auto& o : t.outputs) block(o.name, UnitOf(o.name), o.values);
  for (const auto& [name, v] : Flags(t)) block(name, "-", AsDoubles(*v));
  return s;
}

}  // namespace fluxcal::tables::internal
