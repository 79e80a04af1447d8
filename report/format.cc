#include "report/format.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>

namespace fluxcal::report {
namespace {

// "12.500" -> "12.5", "3.000" -> "3", "2.50e-06" -> "2.5e-06"; "-0" -> "0".
std::string Tidy(std::string s) {
  const size_t e = s.find_first_of("eE");
  std::string mant = e == std::string::npos ? s : s.substr(0, e);
  const std::string exp = e == std::string::npos ? "" : s.substr(e);
  if (mant.find('.') != std::string::npos) {
    while (!mant.empty() && mant.back() == '0') mant.pop_back();
    if (!mant.empty() && mant.back() == '.') mant.pop_back();
  }
  if (mant == "-0") mant = "0";
  return mant + exp;
}

std::string Fixed(double v, int decimals) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", std::max(0, decimals), v);
  return b;
}

// Unit of an SI suffix and whether it takes an engineering prefix.
struct SuffixUnit {
  const char* suffix;
  const char* unit;
  bool prefix;
};
constexpr SuffixUnit kSuffixes[] = {
    {"_s", "s", true},   {"_ohm", "ohm", true}, {"_h", "H", true},      {"_wb", "Wb", true},
    {"_a", "A", true},   {"_v", "V", true},     {"_hz", "Hz", true},    {"_nm", "N m", false},
    {"_c", "degC", false}, {"_rad", "rad", false}, {"_rpm", "rpm", false}, {"_w", "W", true},
};

bool EndsWith(const std::string& s, const std::string& t) {
  return s.size() >= t.size() && s.compare(s.size() - t.size(), t.size(), t) == 0;
}

// The rounding of the quantity whose unit follows position `at` of
// `text` (" A", " V", " %", ...), or nullptr.
const Rounding* UnitAfter(const std::string& text, size_t at) {
  static constexpr Rounding kPercentText{3, 0.01};
  static const std::pair<const char*, const Rounding*> kUnits[] = {
      {"A", &kCurrentA},     {"V", &kVoltageV},       {"%", &kPercentText},      {"rpm", &kSpeedRpm},
      {"Wb", &kFluxWb},      {"mWb", &kFluxMwb},      {"mH", &kInductanceMh},    {"uH", &kInductanceUh},
      {"N m", &kTorqueNm},   {"sigma", &kSigma},      {"ohm", &kResistanceOhm},  {"degC", &kTemperatureC}};
  if (at >= text.size() || text[at] != ' ') return nullptr;
  for (const auto& [unit, r] : kUnits) {
    const size_t n = std::string(unit).size();
    if (text.compare(at + 1, n, unit) != 0) continue;
    const size_t end = at + 1 + n;
    if (end < text.size() && (std::isalnum(static_cast<unsigned char>(text[end])) || text[end] == '_')) continue;
    return r;
  }
  return nullptr;
}

}  // namespace

std::string Num(double v, Rounding r) {
  if (std::isnan(v)) return "n/a";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  double x = v;
  if (r.resolution > 0) x = std::round(x / r.resolution) * r.resolution;
  if (x == 0) return "0";
  const int digits = std::max(1, r.digits);
  const double a = std::abs(x);
  if (a >= 1e7 || a < 1e-4) {
    char b[64];
    std::snprintf(b, sizeof b, "%.*e", digits - 1, x);
    return Tidy(b);
  }
  int decimals = digits - 1 - static_cast<int>(std::floor(std::log10(a)));
  if (r.resolution > 0) {
    decimals = std::min(decimals, static_cast<int>(std::ceil(-std::log10(r.resolution) - 1e-9)));
  }
  if (decimals < 0) {
    // More integer digits than significant ones: 1234567 to 3 digits is
    // 1230000, written out (no exponent inside the fixed range).
    const double p = std::pow(10.0, -decimals);
    x = std::round(x / p) * p;
    decimals = 0;
  }
  return Tidy(Fixed(x, decimals));
}

std::string Num(double v, Rounding r, const std::string& unit) {
  return unit.empty() ? Num(v, r) : Num(v, r) + " " + unit;
}

std::string Range(double lo, double hi, Rounding r, const std::string& unit) {
  return Num(lo, r) + " .. " + Num(hi, r, unit);
}

std::string ValueWithStd(const std::string& name, double value, double sd) {
  const SuffixUnit* su = nullptr;
  for (const auto& s : kSuffixes) {
    if (EndsWith(name, s.suffix) && (su == nullptr || std::string(s.suffix).size() > std::string(su->suffix).size())) {
      su = &s;
    }
  }
  std::string unit = su != nullptr ? su->unit : "";
  double scale = 1;
  if (su != nullptr && su->prefix && std::isfinite(value) && value != 0) {
    // Engineering prefix: the value between 1 and 1000 of the unit shown.
    static constexpr std::pair<int, const char*> kPrefixes[] = {{-12, "p"}, {-9, "n"}, {-6, "u"}, {-3, "m"},
                                                                {0, ""},    {3, "k"},  {6, "M"}};
    const int e3 = std::clamp(static_cast<int>(std::floor(std::log10(std::abs(value)) / 3 + 1e-9)) * 3, -12, 6);
    for (const auto& [e, p] : kPrefixes) {
      if (e == e3) {
        scale = std::pow(10.0, -e);
        unit = std::string(p) + unit;
      }
    }
  }
  const double v = value * scale;
  if (!(sd > 0) || !std::isfinite(sd)) return Num(v, Rounding{4, 0}, unit);
  const double s = sd * scale;
  // Two significant digits of the deviation, the value to the same place.
  const int decimals = 1 - static_cast<int>(std::floor(std::log10(s) + 1e-9));
  if (decimals >= 0) {
    auto fixed = [&](double x) {
      std::string t = Fixed(x, decimals);
      return t == "-0" || t.find_first_not_of("-0.") == std::string::npos ? Fixed(0.0, decimals) : t;
    };
    return fixed(v) + (unit.empty() ? "" : " " + unit) + " ± " + fixed(s) + (unit.empty() ? "" : " " + unit);
  }
  const double p = std::pow(10.0, -decimals);
  return Num(std::round(v / p) * p, Rounding{15, 0}, unit) + " ± " + Num(std::round(s / p) * p, Rounding{15, 0}, unit);
}

std::string RoundNumbersInText(const std::string& text, int digits) {
  std::string out;
  out.reserve(text.size());
  auto word_char = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; };
  size_t i = 0;
  while (i < text.size()) {
    const char c = text[i];
    const bool starts = std::isdigit(static_cast<unsigned char>(c)) ||
                        (c == '-' && i + 1 < text.size() && std::isdigit(static_cast<unsigned char>(text[i + 1])));
    const bool glued = i > 0 && (word_char(text[i - 1]) || text[i - 1] == '.');
    if (!starts || glued) {
      out += c;
      ++i;
      continue;
    }
    // One number token: -?digits(.digits)?(e[+-]?digits)?
    size_t j = i + (c == '-' ? 1 : 0);
    while (j < text.size() && std::isdigit(static_cast<unsigned char>(text[j]))) ++j;
    bool fraction = false, exponent = false;
    if (j + 1 < text.size() && text[j] == '.' && std::isdigit(static_cast<unsigned char>(text[j + 1]))) {
      fraction = true;
      ++j;
      while (j < text.size() && std::isdigit(static_cast<unsigned char>(text[j]))) ++j;
    }
    if (j < text.size() && (text[j] == 'e' || text[j] == 'E')) {
      size_t k = j + 1;
      if (k < text.size() && (text[k] == '+' || text[k] == '-')) ++k;
      if (k < text.size() && std::isdigit(static_cast<unsigned char>(text[k]))) {
        exponent = true;
        j = k;
        while (j < text.size() && std::isdigit(static_cast<unsigned char>(text[j]))) ++j;
      }
    }
    // Part of a word or a dotted version ("p003", "1.2.3", "e70b..."):
    // copied as it is, with the rest of the word.
    if (j < text.size() && (word_char(text[j]) || (text[j] == '.' && j + 1 < text.size() &&
                                                   std::isdigit(static_cast<unsigned char>(text[j + 1]))))) {
      while (j < text.size() && (word_char(text[j]) || text[j] == '.')) ++j;
      out.append(text, i, j - i);
      i = j;
      continue;
    }
    const std::string token = text.substr(i, j - i);
    // A unit after the number rounds it as that quantity ("0.04947 A" is
    // "0.05 A"); without one, to `digits`.
    if (const Rounding* r = UnitAfter(text, j); r != nullptr && (fraction || exponent)) {
      out += Num(std::strtod(token.c_str(), nullptr), *r);
      i = j;
      continue;
    }
    if (!fraction && !exponent) {
      out += token == "-0" ? "0" : token;
    } else {
      // Significant digits of the mantissa as written.
      const std::string mant = token.substr(0, token.find_first_of("eE"));
      size_t sig = 0;
      bool leading = true;
      for (char d : mant) {
        if (!std::isdigit(static_cast<unsigned char>(d))) continue;
        if (leading && d == '0') continue;
        leading = false;
        ++sig;
      }
      const double v = std::strtod(token.c_str(), nullptr);
      if (v == 0) {
        out += "0";
      } else if (sig > static_cast<size_t>(digits) || exponent) {
        out += Num(v, Rounding{digits, 0});
      } else {
        out += token;
      }
    }
    i = j;
  }
  return out;
}

}  // namespace fluxcal::report
