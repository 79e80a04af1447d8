// Per-quantity scales and fixed-point representation of exported tables
// (tables.h, docs/tables.md "Fixed point").
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "absl/strings/str_format.h"
#include "tables/tables.h"

namespace fluxcal::tables {

double FullScale(double max_abs) {
  if (!(max_abs > 0) || !std::isfinite(max_abs)) return 1.0;
  // f = 2^e with e = ceil(log2(max_abs / fill)); the loops correct the
  // rounding of log2 so that f is the smallest such power of two.
  double f = std::ldexp(1.0, static_cast<int>(std::ceil(std::log2(max_abs / kFixedPointFill))));
  while (kFixedPointFill * f < max_abs) f *= 2;
  while (kFixedPointFill * (f / 2) >= max_abs) f /= 2;
  return f;
}

std::vector<QuantityScale> QuantityScales(const Table& t, CType ct) {
  std::vector<QuantityScale> out;
  std::vector<double> max_abs;
  auto add = [&](const std::string& name, const std::vector<double>& v) {
    const std::string unit = UnitOf(name);
    size_t k = 0;
    while (k < out.size() && out[k].unit != unit) ++k;
    if (k == out.size()) {
      out.push_back({});
      out.back().unit = unit;
      max_abs.push_back(0.0);
    }
    out[k].arrays.push_back(name);
    for (double x : v) max_abs[k] = std::max(max_abs[k], std::abs(x));
  };
  for (const auto& a : t.axes) add(a.name, a.values);
  for (const auto& o : t.outputs) add(o.name, o.values);
  // The scalars of a quantity (i_max_a for the currents, speed_max_rpm for
  // the speed axis) lie within its full scale too.
  for (const auto& sc : Scalars(t)) {
    for (size_t k = 0; k < out.size(); ++k) {
      if (out[k].unit == sc.unit) max_abs[k] = std::max(max_abs[k], std::abs(sc.value));
    }
  }
  const int bits = FixedPointBits(ct);
  for (size_t k = 0; k < out.size(); ++k) {
    QuantityScale& q = out[k];
    q.bits = bits;
    q.full_scale = FullScale(max_abs[k]);
    q.lsb = bits > 0 ? std::ldexp(q.full_scale, -(bits - 1)) : 0.0;
    q.offset = 0.0;
    q.min_value = -q.full_scale;
    q.max_value = q.full_scale - q.lsb;
  }
  return out;
}

const QuantityScale* ScaleOf(const std::vector<QuantityScale>& scales, const std::string& name) {
  for (const auto& q : scales) {
    for (const auto& a : q.arrays) {
      if (a == name) return &q;
    }
  }
  return nullptr;
}

absl::StatusOr<std::vector<int64_t>> Quantize(const std::vector<double>& values, const QuantityScale& s,
                                              const std::string& what) {
  if (s.bits < 2 || s.bits > 32 || !(s.lsb > 0)) {
    return absl::InvalidArgumentError(absl::StrFormat("%s: not a fixed-point scale (%d bits, LSB %g)", what, s.bits, s.lsb));
  }
  const double lo = -std::ldexp(1.0, s.bits - 1), hi = std::ldexp(1.0, s.bits - 1) - 1;
  std::vector<int64_t> raw(values.size());
  for (size_t k = 0; k < values.size(); ++k) {
    // raw = round((v - offset) / lsb), half away from zero; with a
    // power-of-two LSB the division is exact, so |v - raw lsb| <= lsb / 2.
    const double r = std::round((values[k] - s.offset) / s.lsb);
    if (!(r >= lo && r <= hi)) {
      return absl::OutOfRangeError(absl::StrFormat(
          "%s[%zu]: %.17g %s does not fit %d-bit fixed point with LSB %.17g %s (range %.17g .. %.17g %s); refused "
          "rather than saturated",
          what, k, values[k], s.unit, s.bits, s.lsb, s.unit, lo * s.lsb + s.offset, hi * s.lsb + s.offset, s.unit));
    }
    raw[k] = static_cast<int64_t>(r);
  }
  return raw;
}

}  // namespace fluxcal::tables
