// Geometry on curves and fields before anything is drawn: which curves
// coincide (so they are drawn once), and contour lines of a gridded field
// (marching squares).
#include <algorithm>
#include <cmath>
#include <map>

#include "plot/plot.h"

namespace fluxcal::plot {

std::vector<size_t> CoincidentGroups(const std::vector<std::vector<double>>& ys, double tol) {
  std::vector<size_t> group(ys.size());
  for (size_t k = 0; k < ys.size(); ++k) {
    group[k] = k;
    for (size_t l = 0; l < k; ++l) {
      if (group[l] != l || ys[l].size() != ys[k].size()) continue;   // compare with group leaders only
      bool same = true;
      for (size_t i = 0; i < ys[k].size() && same; ++i) {
        if (std::isfinite(ys[k][i]) && std::isfinite(ys[l][i])) same = std::abs(ys[k][i] - ys[l][i]) <= tol;
        else same = std::isfinite(ys[k][i]) == std::isfinite(ys[l][i]);
      }
      if (same) {
        group[k] = l;
        break;
      }
    }
  }
  return group;
}

std::vector<Polyline> ContourLines(const std::vector<double>& xs, const std::vector<double>& ys,
                                   const std::vector<double>& z, double level) {
  const size_t nx = xs.size(), ny = ys.size();
  std::vector<Polyline> out;
  if (nx < 2 || ny < 2 || z.size() != nx * ny) return out;
  using P = std::pair<double, double>;
  std::vector<std::pair<P, P>> segs;
  auto at = [&](size_t i, size_t j) { return z[j * nx + i]; };
  auto lerp = [&](double xa, double ya, double za, double xb, double yb, double zb) {
    const double t = za == zb ? 0.5 : (level - za) / (zb - za);
    return P{xa + t * (xb - xa), ya + t * (yb - ya)};
  };
  for (size_t j = 0; j + 1 < ny; ++j) {
    for (size_t i = 0; i + 1 < nx; ++i) {
      // Corners counter-clockwise from bottom-left.
      const double x0 = xs[i], x1 = xs[i + 1], y0 = ys[j], y1 = ys[j + 1];
      const double z0 = at(i, j), z1 = at(i + 1, j), z2 = at(i + 1, j + 1), z3 = at(i, j + 1);
      if (std::isnan(z0) || std::isnan(z1) || std::isnan(z2) || std::isnan(z3)) continue;
      const int c = (z0 >= level) | ((z1 >= level) << 1) | ((z2 >= level) << 2) | ((z3 >= level) << 3);
      if (c == 0 || c == 15) continue;
      // Each edge interpolated from its lower-index corner, so a crossing
      // shared by two cells is computed bit-identically from both (the
      // joining below relies on exact equality).
      const P b = lerp(x0, y0, z0, x1, y0, z1);   // bottom edge
      const P r = lerp(x1, y0, z1, x1, y1, z2);   // right
      const P t = lerp(x0, y1, z3, x1, y1, z2);   // top
      const P l = lerp(x0, y0, z0, x0, y1, z3);   // left
      const bool centre_high = (z0 + z1 + z2 + z3) / 4 >= level;
      switch (c) {
        case 1: case 14: segs.push_back({l, b}); break;
        case 2: case 13: segs.push_back({b, r}); break;
        case 3: case 12: segs.push_back({l, r}); break;
        case 4: case 11: segs.push_back({r, t}); break;
        case 6: case 9: segs.push_back({b, t}); break;
        case 7: case 8: segs.push_back({l, t}); break;
        case 5:   // z0 and z2 high
          if (centre_high) { segs.push_back({l, t}); segs.push_back({b, r}); }
          else { segs.push_back({l, b}); segs.push_back({r, t}); }
          break;
        case 10:  // z1 and z3 high
          if (centre_high) { segs.push_back({l, b}); segs.push_back({r, t}); }
          else { segs.push_back({l, t}); segs.push_back({b, r}); }
          break;
      }
    }
  }
  // Join segments that share an end point.
  std::multimap<P, size_t> by_end;
  for (size_t k = 0; k < segs.size(); ++k) {
    by_end.insert({segs[k].first, k});
    by_end.insert({segs[k].second, k});
  }
  std::vector<bool> used(segs.size(), false);
  auto take_next = [&](const P& p) -> std::optional<P> {
    auto range = by_end.equal_range(p);
    for (auto it = range.first; it != range.second; ++it) {
      const size_t k = it->second;
      if (used[k]) continue;
      used[k] = true;
      return segs[k].first == p ? segs[k].second : segs[k].first;
    }
    return std::nullopt;
  };
  for (size_t k = 0; k < segs.size(); ++k) {
    if (used[k]) continue;
    used[k] = true;
    Polyline line = {segs[k].first, segs[k].second};
    while (auto n = take_next(line.back())) line.push_back(*n);
    while (auto n = take_next(line.front())) line.insert(line.begin(), *n);
    out.push_back(std::move(line));
  }
  return out;
}

}  // namespace fluxcal::plot
