// The CDFX export format: ASAM CDF 2.0 (docs/tables.md).
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "tables/internal_formats.h"
#include "tables/tables.h"

namespace fluxcal::tables::internal {
namespace {

std::string XmlEscape(const std::string& s) {
  return absl::StrReplaceAll(s, {{"&", "&amp;"}, {"<", "&lt;"}, {">", "&gt;"}, {"\"", "&quot;"}});
}

}  // namespace

std::string Cdfx(const Table& t) {
  // ASAM CDF 2.0 (MSRSW): MSRSW > SW-SYSTEMS > SW-SYSTEM > SW-INSTANCE-SPEC >
  // SW-INSTANCE-TREE > SW-INSTANCE. Scalars are category VALUE (V), text
  // ASCII (VT), outputs and flags CURVE (1 axis) or MAP (2 axes) with
  // STD_AXIS containers in axis order X, Y; a MAP holds one VG per X value
  // with the values over Y. The subset emitted is described by
  // tests/tables/cdf_subset.dtd.
  std::string s =
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<!DOCTYPE MSRSW PUBLIC \"-//ASAM//DTD CALIBRATION DATA FORMAT:V2.0.0:LAI:IAI:XML:CDF200.XSD//EN\" \"cdf_v2.0.0.sl.dtd\">\n";
  absl::StrAppend(&s, "<!-- fluxcal ", TableTitle(t), " table; axis order: ", OneLine(AxisOrder(t)), ". payload_crc32 ", Crc(t),
                    ", payload_sha256 ", t.sha256, ": over the values (fluxcal docs/tables.md), not over this file. -->\n");
  s += "<MSRSW>\n  <SHORT-NAME>fluxcal</SHORT-NAME>\n  <CATEGORY>CDF20</CATEGORY>\n  <SW-SYSTEMS>\n    <SW-SYSTEM>\n";
  s += absl::StrFormat("      <SHORT-NAME>%s</SHORT-NAME>\n", XmlEscape(t.serial.empty() ? "fluxcal" : t.serial));
  s += "      <SW-INSTANCE-SPEC>\n        <SW-INSTANCE-TREE>\n          <SHORT-NAME>fluxcal</SHORT-NAME>\n"
       "          <CATEGORY>NO_VCD</CATEGORY>\n";
  const std::string in = "          ";
  auto head = [&](const std::string& name, const std::string& long_name, const char* cat) {
    absl::StrAppend(&s, in, "<SW-INSTANCE>\n", in, "  <SHORT-NAME>", Label(t, name), "</SHORT-NAME>\n", in,
                      "  <LONG-NAME>", XmlEscape(OneLine(long_name)), "</LONG-NAME>\n", in, "  <CATEGORY>", cat,
                      "</CATEGORY>\n");
  };
  for (const auto& sc : Scalars(t)) {
    head(sc.name, sc.description, "VALUE");
    absl::StrAppend(&s, in, "  <SW-VALUE-CONT>\n", in, "    <UNIT-DISPLAY-NAME>", sc.unit, "</UNIT-DISPLAY-NAME>\n", in,
                      "    <SW-VALUES-PHYS><V>", Num(sc.value), "</V></SW-VALUES-PHYS>\n", in, "  </SW-VALUE-CONT>\n", in,
                      "</SW-INSTANCE>\n");
  }
  for (const auto& [k, v] : TextFields(t)) {
    head(k, k, "ASCII");
    absl::StrAppend(&s, in, "  <SW-VALUE-CONT>\n", in, "    <SW-VALUES-PHYS><VT>", XmlEscape(OneLine(v)),
                      "</VT></SW-VALUES-PHYS>\n", in, "  </SW-VALUE-CONT>\n", in, "</SW-INSTANCE>\n");
  }
  const bool map = t.axes.size() > 1;
  const size_t n0 = t.axes[0].values.size(), n1 = map ? t.axes[1].values.size() : 1;
  // The file is mostly value lines (a 43 x 31 fw map: ~10^4 of them): the
  // string is sized once, and each line is its fixed prefix, the number and
  // "</V>\n", appended in place.
  s.reserve(s.size() + (t.outputs.size() + Flags(t).size()) * (n0 * n1 * 48 + (n0 + n1) * 40 + 1024));
  const std::string value_prefix = absl::StrCat(in, map ? "        " : "      ", "<V>");
  const std::string axis_prefix = absl::StrCat(in, "        <V>");
  // `value(k)` appends the k-th value's number.
  auto table = [&](const std::string& name, const std::string& unit, const auto& value, const std::string& what) {
    head(name, what, map ? "MAP" : "CURVE");
    absl::StrAppend(&s, in, "  <SW-VALUE-CONT>\n", in, "    <UNIT-DISPLAY-NAME>", unit, "</UNIT-DISPLAY-NAME>\n", in,
                      "    <SW-VALUES-PHYS>\n");
    for (size_t i = 0; i < n0; ++i) {
      if (map) absl::StrAppend(&s, in, "      <VG>\n");
      for (size_t j = 0; j < n1; ++j) {
        s += value_prefix;
        value(i * n1 + j);
        s += "</V>\n";
      }
      if (map) absl::StrAppend(&s, in, "      </VG>\n");
    }
    absl::StrAppend(&s, in, "    </SW-VALUES-PHYS>\n", in, "  </SW-VALUE-CONT>\n", in, "  <SW-AXIS-CONTS>\n");
    for (const auto& a : t.axes) {
      absl::StrAppend(&s, in, "    <SW-AXIS-CONT>\n", in, "      <CATEGORY>STD_AXIS</CATEGORY>\n", in,
                        "      <UNIT-DISPLAY-NAME>", UnitOf(a.name), "</UNIT-DISPLAY-NAME>\n", in,
                        "      <SW-VALUES-PHYS>\n");
      for (double v : a.values) {
        s += axis_prefix;
        AppendNum(&s, v);
        s += "</V>\n";
      }
      absl::StrAppend(&s, in, "      </SW-VALUES-PHYS>\n", in, "    </SW-AXIS-CONT>\n");
    }
    absl::StrAppend(&s, in, "  </SW-AXIS-CONTS>\n", in, "</SW-INSTANCE>\n");
  };
  std::vector<std::string> axis_names;
  for (const auto& a : t.axes) axis_names.push_back(a.name);
  const std::string over = absl::StrJoin(axis_names, " x ");
  for (const auto& o : t.outputs) {
    table(o.name, UnitOf(o.name), [&](size_t k) { AppendNum(&s, o.values[k]); }, absl::StrCat(o.name, " over ", over));
  }
  for (const auto& [name, v] : Flags(t)) {
    // A flag is 0 or 1: its digit (what "%.17g" writes for a small whole
    // number); any other value as a number.
    const std::vector<uint8_t>& f = *v;
    table(name, "-", [&](size_t k) { f[k] <= 9 ? s.push_back(static_cast<char>('0' + f[k])) : AppendNum(&s, f[k]); },
          absl::StrCat(name, " (0/1 per cell) over ", over));
  }
  s += "        </SW-INSTANCE-TREE>\n      </SW-INSTANCE-SPEC>\n    </SW-SYSTEM>\n  </SW-SYSTEMS>\n</MSRSW>\n";
  return s;
}

}  // namespace fluxcal::tables::internal
