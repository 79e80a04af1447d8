// The csv and json export formats (docs/tables.md).
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "nlohmann/json.hpp"
#include "tables/internal_formats.h"
#include "tables/tables.h"

namespace fluxcal::tables::internal {

std::string Csv(const Table& t) {
  // Comment header: "# key: value" lines, then one row per cell (X slowest).
  std::string s = absl::StrFormat("# fluxcal %s table\n", TableTitle(t));
  for (const auto& [k, v] : TextFields(t)) s += absl::StrCat("# ", k, ": ", OneLine(v), "\n");
  s += absl::StrCat("# calibration_version: ", t.calibration_version, "\n");
  for (const auto& sc : Scalars(t)) {
    if (sc.name == "calibration_version") continue;
    s += absl::StrCat("# ", sc.name, ": ", Num(sc.value), " ", sc.unit, " (", sc.description, ")\n");
  }
  s += absl::StrCat("# axis_order: ", AxisOrder(t), "\n");
  s += absl::StrCat("# payload_crc32: ", Crc(t), " (over the values, docs/tables.md; not a file checksum)\n");
  s += absl::StrCat("# payload_sha256: ", t.sha256, " (over the values, docs/tables.md; not a file checksum)\n");
  std::vector<std::string> head;
  for (const auto& a : t.axes) head.push_back(a.name);
  for (const auto& o : t.outputs) head.push_back(o.name);
  for (const auto& [name, v] : Flags(t)) head.push_back(name);
  s += absl::StrJoin(head, ",") + "\n";
  const size_t n0 = t.axes[0].values.size();
  const size_t n1 = t.axes.size() > 1 ? t.axes[1].values.size() : 1;
  for (size_t i = 0; i < n0; ++i) {
    for (size_t j = 0; j < n1; ++j) {
      std::vector<std::string> row = {Num(t.axes[0].values[i])};
      if (t.axes.size() > 1) row.push_back(Num(t.axes[1].values[j]));
      for (const auto& o : t.outputs) row.push_back(Num(o.values[i * n1 + j]));
      for (const auto& [name, v] : Flags(t)) row.push_back((*v)[i * n1 + j] ? "1" : "0");
      s += absl::StrJoin(row, ",") + "\n";
    }
  }
  return s;
}

std::string Json(const Table& t) {
  nlohmann::json j;
  // v2: the checksums are named payload_crc32 / payload_sha256 (v1 called
  // them crc32 / sha256, read as file checksums), and limits, verdict,
  // release state and flags travel in the file.
  j["format"] = "fluxcal.table.v2";
  j["kind"] = t.kind;
  if (t.kind == "envelope") j["direction"] = t.envelope_generating ? "generating" : "motoring";
  for (const auto& [k, v] : TextFields(t)) j[k] = v;
  j["calibration_version"] = t.calibration_version;
  nlohmann::json sc = nlohmann::json::object();
  for (const auto& x : Scalars(t)) {
    if (x.name == "calibration_version") continue;
    sc[x.name] = {{"value", x.value}, {"unit", x.unit}, {"description", x.description}};
  }
  j["scalars"] = sc;
  j["axis_order"] = AxisOrder(t);
  j["payload_crc32"] = Crc(t);
  j["payload_sha256"] = t.sha256;
  for (const auto& a : t.axes) j["axes"].push_back({{"name", a.name}, {"unit", UnitOf(a.name)}, {"values", a.values}});
  for (const auto& o : t.outputs) j["outputs"].push_back({{"name", o.name}, {"unit", UnitOf(o.name)}, {"values", o.values}});
  for (const auto& [name, v] : Flags(t)) j[name] = *v;
  return j.dump(1) + "\n";
}

}  // namespace fluxcal::tables::internal
