// The page's words: HTML escaping, table rows, the time of writing, and
// JSON values and unit-suffixed names as rounded text (report/format.h
// rounds the numbers).
#include <ctime>

#include "absl/strings/match.h"
#include "plot/plot.h"
#include "report/format.h"
#include "report/internal.h"

namespace fluxcal::report::internal {

std::string H(const std::string& s) { return plot::Escape(s); }   // HTML text escape

std::string NowUtc() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

std::vector<double> Linspace(double a, double b, int n) {
  std::vector<double> v(n);
  for (int k = 0; k < n; ++k) v[k] = n == 1 ? a : a + (b - a) * k / (n - 1);
  return v;
}

// A JSON value as text: strings unquoted (their numbers rounded, they were
// written by another program), numbers rounded by `r`, "" when absent.
std::string ValueText(const nlohmann::json& v, Rounding r) {
  if (v.is_null()) return "";
  if (v.is_string()) return RoundNumbersInText(v.get<std::string>());
  if (v.is_number()) return Num(v.get<double>(), r);
  return RoundNumbersInText(v.dump());
}
std::string JsonText(const nlohmann::json& j, const char* key, Rounding r) {
  if (!j.is_object() || !j.contains(key)) return "";
  return ValueText(j[key], r);
}
// A relative residual (0.0123) as a percentage ("1.2 %").
std::string PercentText(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return JsonText(j, key);
  return Num(100 * j[key].get<double>(), kPercent, "%");
}

std::string Row(const std::string& k, const std::string& v) {
  return "<tr><th>" + H(k) + "</th><td>" + v + "</td></tr>\n";
}

// How a table axis or output named with its unit suffix is rounded.
Rounding RoundingOf(const std::string& name) {
  if (absl::EndsWith(name, "_a")) return kCurrentA;
  if (absl::EndsWith(name, "_nm")) return kTorqueNm;
  if (absl::EndsWith(name, "_rpm")) return kSpeedRpm;
  if (absl::EndsWith(name, "_wb")) return kFluxWb;
  if (absl::EndsWith(name, "_v")) return kVoltageV;
  return Rounding{4, 0};
}
std::string UnitOf(const std::string& name) {
  if (absl::EndsWith(name, "_a")) return "A";
  if (absl::EndsWith(name, "_nm")) return "N m";
  if (absl::EndsWith(name, "_rpm")) return "rpm";
  if (absl::EndsWith(name, "_wb")) return "Wb";
  if (absl::EndsWith(name, "_v")) return "V";
  return "";
}

}  // namespace fluxcal::report::internal
