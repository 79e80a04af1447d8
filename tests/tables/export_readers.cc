// The readers of export_readers.h.
#include "tests/tables/export_readers.h"

#include <regex>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tinyxml2.h"

namespace fluxcal::tables::readers {
namespace {

const std::set<std::string> kTextKeys = {"serial", "model", "created_utc", "fluxcal_version", "verdict",
                                         "release_state"};

double ToD(std::string s) {
  s = std::string(absl::StripSuffix(absl::StripAsciiWhitespace(s), "f"));
  double v;
  EXPECT_TRUE(absl::SimpleAtod(s, &v)) << "not a number: '" << s << "'";
  return v;
}

std::vector<double> Numbers(const std::string& s) {
  std::vector<double> v;
  for (auto tok : absl::StrSplit(s, absl::ByAnyChar(" ,\n\t"), absl::SkipWhitespace())) v.push_back(ToD(std::string(tok)));
  return v;
}

// "X = torque_nm (first axis), Y = speed_rpm ..." -> {torque_nm, speed_rpm}.
std::vector<std::string> AxisNames(const std::string& order) {
  std::vector<std::string> out;
  for (const char* key : {"X = ", "Y = "}) {
    const size_t p = order.find(key);
    if (p == std::string::npos) continue;
    const size_t b = p + 4, e = order.find(' ', b);
    out.push_back(order.substr(b, e - b));
  }
  return out;
}

// Whether `line` is a comment of the export (`lead`: CSV "# ", DCM "* ").
// For one with a "key: value", *key and *rest are set and a provenance key
// (kTextKeys) is recorded in p->text; *key is empty for one without.
bool IsComment(const std::string& line, const char* lead, Parsed* p, std::string* key, std::string* rest) {
  if (!absl::StartsWith(line, lead)) return false;
  key->clear();
  const size_t c = line.find(": ");
  if (c == std::string::npos) return true;
  *key = line.substr(2, c - 2);
  *rest = line.substr(c + 2);
  if (kTextKeys.count(*key)) p->text[*key] = *rest;
  return true;
}

}  // namespace

// "FLUXCAL_FW_ID_A" -> "id_a" ("FLUXCAL_FW_UDC300V_ID_A" of a Udc axis' table).
std::string Local(const Table& t, const std::string& ident) {
  const std::string prefix = absl::AsciiStrToLower(
      absl::StrCat("fluxcal_", t.kind, "_", t.label_tag, t.label_tag.empty() ? "" : "_"));
  std::string s = absl::AsciiStrToLower(ident);
  return absl::StartsWith(s, prefix) ? s.substr(prefix.size()) : s;
}

Parsed Expected(const Table& t) {
  Parsed p;
  for (const auto& s : Scalars(t)) p.scalars[s.name] = s.value;
  for (const auto& [k, v] : TextFields(t)) p.text[k] = v;
  for (const auto& a : t.axes) { p.axis_names.push_back(a.name); p.axes.push_back(a.values); }
  for (const auto& o : t.outputs) p.arrays[o.name] = o.values;
  for (const auto& [name, v] : Flags(t)) p.arrays[name] = std::vector<double>(v->begin(), v->end());
  p.payload_crc32 = absl::StrFormat("%08x", t.crc32);
  p.payload_sha256 = t.sha256;
  return p;
}

Parsed ParseCsv(const std::string& bytes) {
  Parsed p;
  std::istringstream in(bytes);
  std::string line;
  std::vector<std::string> cols;
  std::vector<std::vector<double>> rows;
  std::string key, rest;
  while (std::getline(in, line)) {
    if (IsComment(line, "# ", &p, &key, &rest)) {
      if (key.empty() || kTextKeys.count(key)) continue;
      if (key == "axis_order") p.axis_names = AxisNames(rest);
      else if (key == "payload_crc32") p.payload_crc32 = rest.substr(0, rest.find(' '));
      else if (key == "payload_sha256") p.payload_sha256 = rest.substr(0, rest.find(' '));
      else p.scalars[key] = ToD(rest.substr(0, rest.find(' ')));
    } else if (cols.empty()) {
      cols = absl::StrSplit(line, ',');
    } else if (!line.empty()) {
      rows.push_back(Numbers(line));
    }
  }
  const size_t na = p.axis_names.size();
  if (na == 0 || rows.empty()) return p;
  std::vector<double> x;
  for (const auto& r : rows) if (x.empty() || r[0] != x.back()) x.push_back(r[0]);
  p.axes.push_back(x);
  if (na == 2) {
    std::vector<double> y;
    for (size_t k = 0; k < rows.size() / x.size(); ++k) y.push_back(rows[k][1]);
    p.axes.push_back(y);
  }
  for (size_t c = na; c < cols.size(); ++c) {
    for (const auto& r : rows) p.arrays[cols[c]].push_back(r[c]);
  }
  return p;
}

Parsed ParseJson(const std::string& bytes) {
  Parsed p;
  const auto j = nlohmann::json::parse(bytes);
  for (const auto& k : kTextKeys) p.text[k] = j.at(k).get<std::string>();
  for (const auto& [k, v] : j.at("scalars").items()) p.scalars[k] = v.at("value").get<double>();
  p.scalars["calibration_version"] = j.at("calibration_version").get<double>();
  for (const auto& a : j.at("axes")) {
    p.axis_names.push_back(a.at("name"));
    p.axes.push_back(a.at("values").get<std::vector<double>>());
  }
  for (const auto& o : j.at("outputs")) p.arrays[o.at("name")] = o.at("values").get<std::vector<double>>();
  // Every flag the exporter writes (tables::Flags names them, in order).
  for (const auto& [f, v] : Flags(Table{})) p.arrays[f] = j.at(f).get<std::vector<double>>();
  p.payload_crc32 = j.at("payload_crc32");
  p.payload_sha256 = j.at("payload_sha256");
  return p;
}

// DCM 2.0: '*' comments, FESTWERT / KENNLINIE / KENNFELD blocks up to END.
Parsed ParseDcm(const Table& t, const std::string& bytes) {
  Parsed p;
  std::istringstream in(bytes);
  std::string line, block, name, unit_x, unit_y;
  std::vector<double> stx, sty;
  std::vector<std::vector<double>> wert;   // one entry per WERT run (per ST/Y for a map)
  bool first_table = true;
  std::string field, rest;
  while (std::getline(in, line)) {
    if (IsComment(line, "* ", &p, &field, &rest)) {
      if (field == "payload_crc32") {
        p.payload_crc32 = rest.substr(0, rest.find(','));
        const size_t s = rest.find("payload_sha256: ");
        p.payload_sha256 = rest.substr(s + 16, 64);
      }
      continue;
    }
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "FESTWERT" || key == "KENNLINIE" || key == "KENNFELD") {
      block = key;
      ls >> name;
      stx.clear(); sty.clear(); wert.clear();
      unit_x.clear(); unit_y.clear();
      p.labels.insert(name);
      p.kinds[Local(t, name)] = key;
    } else if (key == "EINHEIT_W" || key == "EINHEIT_X" || key == "EINHEIT_Y") {
      std::string u;
      std::getline(ls, u);
      u = std::string(absl::StripAsciiWhitespace(u));
      if (u.size() >= 2 && u.front() == '"' && u.back() == '"') u = u.substr(1, u.size() - 2);
      (key == "EINHEIT_W" ? p.units[Local(t, name)] : key == "EINHEIT_X" ? unit_x : unit_y) = u;
    } else if (key == "ST/X") {
      double v; while (ls >> v) stx.push_back(v);
    } else if (key == "ST/Y") {
      double v; ls >> v; sty.push_back(v);
      wert.emplace_back();
    } else if (key == "WERT") {
      if (wert.empty()) wert.emplace_back();
      double v; while (ls >> v) wert.back().push_back(v);
    } else if (key == "END") {
      const std::string n = Local(t, name);
      if (block == "FESTWERT") {
        p.scalars[n] = wert.at(0).at(0);
      } else if (block == "KENNLINIE") {
        p.arrays[n] = wert.at(0);
        if (first_table) p.axes = {stx}, p.axis_units = {unit_x};
      } else {
        // KENNFELD nx ny: WERT run j holds the values over X at Y = sty[j].
        std::vector<double> flat(stx.size() * sty.size());
        for (size_t j = 0; j < sty.size(); ++j)
          for (size_t i = 0; i < stx.size(); ++i) flat[i * sty.size() + j] = wert.at(j).at(i);
        p.arrays[n] = flat;
        if (first_table) p.axes = {stx, sty}, p.axis_units = {unit_x, unit_y};
      }
      if (block != "FESTWERT") first_table = false;
      block.clear();
    }
  }
  return p;
}

// CDF 2.0 through tinyxml2: VALUE / ASCII / CURVE / MAP instances.
Parsed ParseCdfx(const Table& t, const std::string& bytes) {
  Parsed p;
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.Parse(bytes.c_str()), tinyxml2::XML_SUCCESS);
  for (auto* n = doc.FirstChild(); n; n = n->NextSibling()) {
    if (auto* c = n->ToComment()) {
      const std::string s = c->Value();
      const size_t a = s.find("payload_crc32 "), b = s.find("payload_sha256 ");
      if (a != std::string::npos) p.payload_crc32 = s.substr(a + 14, 8);
      if (b != std::string::npos) p.payload_sha256 = s.substr(b + 15, 64);
    }
  }
  auto* tree = doc.FirstChildElement("MSRSW")->FirstChildElement("SW-SYSTEMS")->FirstChildElement("SW-SYSTEM")
                   ->FirstChildElement("SW-INSTANCE-SPEC")->FirstChildElement("SW-INSTANCE-TREE");
  bool first_table = true;
  for (auto* inst = tree->FirstChildElement("SW-INSTANCE"); inst; inst = inst->NextSiblingElement("SW-INSTANCE")) {
    const std::string label = inst->FirstChildElement("SHORT-NAME")->GetText();
    const std::string n = Local(t, label);
    const std::string cat = inst->FirstChildElement("CATEGORY")->GetText();
    p.labels.insert(label);
    p.kinds[n] = cat;
    auto* cont = inst->FirstChildElement("SW-VALUE-CONT");
    if (auto* u = cont->FirstChildElement("UNIT-DISPLAY-NAME"); u != nullptr && u->GetText() != nullptr) {
      p.units[n] = u->GetText();
    }
    auto* phys = cont->FirstChildElement("SW-VALUES-PHYS");
    if (cat == "VALUE") {
      p.scalars[n] = std::stod(phys->FirstChildElement("V")->GetText());
    } else if (cat == "ASCII") {
      const char* s = phys->FirstChildElement("VT")->GetText();
      p.text[n] = s ? s : "";
    } else {
      std::vector<double> flat;
      if (cat == "MAP") {
        for (auto* vg = phys->FirstChildElement("VG"); vg; vg = vg->NextSiblingElement("VG"))
          for (auto* v = vg->FirstChildElement("V"); v; v = v->NextSiblingElement("V")) flat.push_back(std::stod(v->GetText()));
      } else {
        for (auto* v = phys->FirstChildElement("V"); v; v = v->NextSiblingElement("V")) flat.push_back(std::stod(v->GetText()));
      }
      p.arrays[n] = flat;
      if (first_table) {
        for (auto* ac = inst->FirstChildElement("SW-AXIS-CONTS")->FirstChildElement("SW-AXIS-CONT"); ac;
             ac = ac->NextSiblingElement("SW-AXIS-CONT")) {
          auto* u = ac->FirstChildElement("UNIT-DISPLAY-NAME");
          p.axis_units.push_back(u != nullptr && u->GetText() != nullptr ? u->GetText() : "");
          std::vector<double> ax;
          for (auto* v = ac->FirstChildElement("SW-VALUES-PHYS")->FirstChildElement("V"); v; v = v->NextSiblingElement("V"))
            ax.push_back(std::stod(v->GetText()));
          p.axes.push_back(ax);
        }
        first_table = false;
      }
    }
  }
  return p;
}

// The C header by pattern: #define scalars, char[] text, arrays, checksums.
Parsed ParseCHeader(const Table& t, const std::string& bytes) {
  Parsed p;
  std::smatch m;
  const std::regex order(R"re(\* axis order: ([^\n]*))re");
  if (std::regex_search(bytes, m, order)) p.axis_names = AxisNames(m[1]);
  const std::regex def(R"re(#define (FLUXCAL_\w+) ([^\s]+)\n)re");
  for (auto it = std::sregex_iterator(bytes.begin(), bytes.end(), def); it != std::sregex_iterator(); ++it) {
    const std::string n = (*it)[1];
    p.labels.insert(n);
    if (absl::EndsWith(n, "_LEN")) continue;
    if (absl::EndsWith(n, "_LSB")) {
      p.lsb[Local(t, n.substr(0, n.size() - 4))] = ToD((*it)[2]);
      continue;
    }
    p.scalars[Local(t, n)] = ToD((*it)[2]);
  }
  const std::regex str(R"re(static const char (\w+)\[\] = "((?:[^"\\]|\\.)*)";)re");
  for (auto it = std::sregex_iterator(bytes.begin(), bytes.end(), str); it != std::sregex_iterator(); ++it) {
    std::string v = (*it)[2];
    v = std::regex_replace(v, std::regex(R"re(\\(.))re"), "$1");
    const std::string n = Local(t, (*it)[1]);
    p.labels.insert((*it)[1]);
    if (n == "payload_sha256") p.payload_sha256 = v; else p.text[n] = v;
  }
  const std::regex crc(R"re(static const uint32_t \w+_payload_crc32 = 0x([0-9a-f]{8})u;)re");
  if (std::regex_search(bytes, m, crc)) p.payload_crc32 = m[1];
  const std::regex arr(
      R"re(static const (double|float|uint8_t|int16_t|int32_t) (\w+)\[(\d+)\] = \{([^}]*)\})re");
  std::map<std::string, std::vector<double>> all;
  for (auto it = std::sregex_iterator(bytes.begin(), bytes.end(), arr); it != std::sregex_iterator(); ++it) {
    const std::string n = Local(t, (*it)[2]);
    p.labels.insert((*it)[2]);
    p.element_types[n] = (*it)[1];
    all[n] = Numbers((*it)[4]);
    EXPECT_EQ(all[n].size(), std::stoul((*it)[3])) << n << ": declared length";
  }
  const std::regex crc_sym(R"re(static const uint32_t (\w+) =)re");
  if (std::regex_search(bytes, m, crc_sym)) p.labels.insert(m[1]);
  for (const auto& a : p.axis_names) { p.axes.push_back(all[a]); all.erase(a); }
  p.arrays = all;
  return p;
}

}  // namespace fluxcal::tables::readers
