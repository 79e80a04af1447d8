#include "simulation/flux_map.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace fluxcal::sim {
namespace {

// Quintic Hermite basis on [0, 1]: index 0..2 = value, first, second
// derivative at t = 0; 3..5 = value, first, second derivative at t = 1.
// f[k][n]: n-th derivative (n = 0, 1, 2) of basis function k at t.
void Quintic(double t, double f[6][3]) {
  const double t2 = t * t, t3 = t2 * t, t4 = t3 * t, t5 = t4 * t;
  f[0][0] = 1 - 10 * t3 + 15 * t4 - 6 * t5;   f[0][1] = -30 * t2 + 60 * t3 - 30 * t4;  f[0][2] = -60 * t + 180 * t2 - 120 * t3;
  f[1][0] = t - 6 * t3 + 8 * t4 - 3 * t5;     f[1][1] = 1 - 18 * t2 + 32 * t3 - 15 * t4; f[1][2] = -36 * t + 96 * t2 - 60 * t3;
  f[2][0] = 0.5 * t2 - 1.5 * t3 + 1.5 * t4 - 0.5 * t5;  f[2][1] = t - 4.5 * t2 + 6 * t3 - 2.5 * t4;  f[2][2] = 1 - 9 * t + 18 * t2 - 10 * t3;
  f[3][0] = 10 * t3 - 15 * t4 + 6 * t5;       f[3][1] = 30 * t2 - 60 * t3 + 30 * t4;   f[3][2] = 60 * t - 180 * t2 + 120 * t3;
  f[4][0] = -4 * t3 + 7 * t4 - 3 * t5;        f[4][1] = -12 * t2 + 28 * t3 - 15 * t4;  f[4][2] = -24 * t + 84 * t2 - 60 * t3;
  f[5][0] = 0.5 * t3 - t4 + 0.5 * t5;         f[5][1] = 1.5 * t2 - 4 * t3 + 2.5 * t4;  f[5][2] = 3 * t - 12 * t2 + 10 * t3;
}

size_t Cell(const std::vector<double>& a, double v) {
  const auto it = std::upper_bound(a.begin(), a.end(), v);
  size_t i = it == a.begin() ? 0 : static_cast<size_t>(it - a.begin()) - 1;
  return std::min(i, a.size() - 2);
}

}  // namespace

absl::StatusOr<GriddedFluxMap> GriddedFluxMap::FromFluxGrid(std::vector<double> x, std::vector<double> y,
                                                            const std::vector<double>& pd,
                                                            const std::vector<double>& pq, double tc) {
  const size_t nx = x.size(), ny = y.size();
  if (nx < 4 || ny < 4) return absl::InvalidArgumentError("flux map: need at least 4 x 4 nodes");
  if (pd.size() != nx * ny || pq.size() != nx * ny) {
    return absl::InvalidArgumentError(absl::StrCat("flux map: expected ", nx * ny, " values per table"));
  }
  for (size_t k = 1; k < nx; ++k) if (!(x[k] > x[k - 1])) return absl::InvalidArgumentError("flux map: id axis not increasing");
  for (size_t k = 1; k < ny; ++k) if (!(y[k] > y[k - 1])) return absl::InvalidArgumentError("flux map: iq axis not increasing");
  if (y[0] != 0.0) return absl::InvalidArgumentError("flux map: iq axis must start at 0 (symmetry mirrors it)");
  GriddedFluxMap m;
  m.x_ = std::move(x);
  m.y_ = std::move(y);
  m.temp_coeff_ = tc;
  const auto& X = m.x_;
  const auto& Y = m.y_;
  auto idx = [&](size_t i, size_t j) { return i * ny + j; };
  // Nodal derivatives by finite differences: the five-point stencil
  // (-f2 + 8 f1 - 8 f-1 + f-2) / 12h, fourth order, where the four
  // neighbours exist and are evenly spaced; otherwise the three-point one.
  // Fourth order keeps the nodal inductances consistent with the nodal flux
  // values to O(h^4), so the interpolant's inductance does not bend within
  // a cell (which HF injection, sampling +-5 A around a point, would see).
  // Evenly spaced over the stencil c-2 .. c+2 (indices may run below 0 on
  // the iq axis, mirrored: -Y[k] at index -k).
  auto even_spacing = [](const std::vector<double>& a, long c) {
    auto at = [&](long k) { return k >= 0 ? a[static_cast<size_t>(k)] : -a[static_cast<size_t>(-k)]; };
    const double h = at(c + 1) - at(c);
    for (long k = c - 2; k < c + 2; ++k) {
      if (std::abs(at(k + 1) - at(k) - h) > 1e-9 * std::abs(h)) return false;
    }
    return true;
  };
  auto dx = [&](const std::vector<double>& v, size_t i, size_t j) {
    if (i >= 2 && i + 2 < nx && even_spacing(X, static_cast<long>(i))) {
      const double h = X[i + 1] - X[i];
      return (-v[idx(i + 2, j)] + 8 * v[idx(i + 1, j)] - 8 * v[idx(i - 1, j)] + v[idx(i - 2, j)]) / (12 * h);
    }
    const size_t a = i == 0 ? 0 : i - 1, b = i + 1 == nx ? i : i + 1;
    return (v[idx(b, j)] - v[idx(a, j)]) / (X[b] - X[a]);
  };
  // d/diq with the mirror image below iq = 0: even functions have zero
  // slope there, odd ones are antisymmetric (v(-y) = -v(y)).
  auto dy = [&](const std::vector<double>& v, size_t i, size_t j, bool odd) {
    auto at = [&](long k) {
      return k >= 0 ? v[idx(i, static_cast<size_t>(k))] : (odd ? -1.0 : 1.0) * v[idx(i, static_cast<size_t>(-k))];
    };
    const long jl = static_cast<long>(j);
    if (j + 2 < ny && even_spacing(Y, jl)) {
      const double h = Y[j + 1] - Y[j];
      return (-at(jl + 2) + 8 * at(jl + 1) - 8 * at(jl - 1) + at(jl - 2)) / (12 * h);
    }
    if (j == 0) return odd ? (v[idx(i, 1)] - (-v[idx(i, 1)])) / (2 * Y[1]) : 0.0;
    const size_t b = j + 1 == ny ? j : j + 1;
    return (v[idx(i, b)] - v[idx(i, j - 1)]) / (Y[b] - Y[j - 1]);
  };
  for (auto& row : m.d_) for (auto& v : row) v.assign(nx * ny, 0.0);
  auto& D = m.d_;
  D[1][0] = pd;   // W'_id = psi_d (even in iq)
  D[0][1] = pq;   // W'_iq = psi_q (odd in iq)
  for (size_t i = 0; i < nx; ++i) {
    for (size_t j = 0; j < ny; ++j) {
      D[2][0][idx(i, j)] = dx(pd, i, j);                                       // Ldd (even)
      D[0][2][idx(i, j)] = dy(pq, i, j, true);                                 // Lqq (even)
      D[1][1][idx(i, j)] = j == 0 ? 0.0 : 0.5 * (dy(pd, i, j, false) + dx(pq, i, j));   // Ldq (odd)
    }
  }
  // Co-energy at the nodes: W' = int psi . di along id at iq = 0, then along
  // iq. Trapezoid with the Euler-Maclaurin end correction
  // -h^2/12 (f'(b) - f'(a)) (f' = the nodal inductances): fourth order, so
  // the nodal W' agrees with the nodal flux and inductance to the same order.
  for (size_t i = 1; i < nx; ++i) {
    const double h = X[i] - X[i - 1];
    D[0][0][idx(i, 0)] = D[0][0][idx(i - 1, 0)] + 0.5 * h * (pd[idx(i, 0)] + pd[idx(i - 1, 0)]) -
                         h * h / 12.0 * (D[2][0][idx(i, 0)] - D[2][0][idx(i - 1, 0)]);
  }
  for (size_t i = 0; i < nx; ++i) {
    for (size_t j = 1; j < ny; ++j) {
      const double h = Y[j] - Y[j - 1];
      D[0][0][idx(i, j)] = D[0][0][idx(i, j - 1)] + 0.5 * h * (pq[idx(i, j)] + pq[idx(i, j - 1)]) -
                           h * h / 12.0 * (D[0][2][idx(i, j)] - D[0][2][idx(i, j - 1)]);
    }
  }
  for (size_t i = 0; i < nx; ++i) {
    for (size_t j = 0; j < ny; ++j) {
      D[2][1][idx(i, j)] = j == 0 ? 0.0 : 0.5 * (dy(D[2][0], i, j, false) + dx(D[1][1], i, j));   // odd
      D[1][2][idx(i, j)] = 0.5 * (dx(D[0][2], i, j) + dy(D[1][1], i, j, true));                     // even
    }
  }
  for (size_t i = 0; i < nx; ++i)
    for (size_t j = 0; j < ny; ++j)
      D[2][2][idx(i, j)] = 0.5 * (dy(D[2][1], i, j, true) + dx(D[1][2], i, j));                      // even
  double wx, wy, a, b, c;
  m.Eval(0.0, 0.0, &wx, &wy, &a, &b, &c);
  m.psi_pm_wb_ = wx;
  return m;
}

GriddedFluxMap GriddedFluxMap::FromModel(const MagneticModel& src, double id_min, double id_max, int n_id,
                                         double iq_max, int n_iq) {
  std::vector<double> x(n_id), y(n_iq), pd, pq;
  for (int i = 0; i < n_id; ++i) x[i] = id_min + (id_max - id_min) * i / (n_id - 1);
  for (int j = 0; j < n_iq; ++j) y[j] = iq_max * j / (n_iq - 1);
  for (double a : x) {
    for (double b : y) {
      const auto f = src.Flux(a, b);
      pd.push_back(f.psi_d_wb);
      pq.push_back(f.psi_q_wb);
    }
  }
  return *FromFluxGrid(x, y, pd, pq);
}

void GriddedFluxMap::Eval(double id, double iq, double* wx, double* wy, double* wxx, double* wyy,
                          double* wxy) const {
  // Outside the grid the co-energy continues as its Taylor polynomial at
  // the nearest edge point, to second order in each variable:
  //   W = sum_{a, b <= 2} W^(a,b)(edge) dx^a / a! dy^b / b!,
  // dx, dy the step past the edge (0 along an axis inside). The flux is
  // that polynomial's gradient, so the map stays reciprocal and continuous
  // with its flux and inductance at the edge; past the id edge psi_d goes
  // on linearly with the edge's Ldd (past the iq edge psi_q with Lqq),
  // and cross saturation continues at the edge's rate. The edge cell's
  // quintic patch extrapolated instead ran away within half a cell: a map
  // ending at id = 0 read Ldd 1.6x its edge value at +0.25 A and 14x at
  // +1 A, which the HF orbit of a point at id = 0 sweeps into and no
  // machine has (docs/simulation.md, "Gridded flux maps beyond their grid").
  const double id0 = std::clamp(id, x_.front(), x_.back()), iq0 = std::min(iq, y_.back());
  double w[3][3];
  Derivatives(id0, iq0, w);
  if (id0 == id && iq0 == iq) {
    *wx = w[1][0];
    *wy = w[0][1];
    *wxx = w[2][0];
    *wyy = w[0][2];
    *wxy = w[1][1];
    return;
  }
  const double dx = id - id0, dy = iq - iq0;
  const double px[3] = {1.0, dx, 0.5 * dx * dx}, py[3] = {1.0, dy, 0.5 * dy * dy};
  // d/dx of dx^a / a! is dx^(a-1) / (a-1)!: px shifted by one.
  *wx = *wy = *wxx = *wyy = *wxy = 0.0;
  for (int b = 0; b < 3; ++b) {
    *wx += (w[1][b] + w[2][b] * dx) * py[b];
    *wxx += w[2][b] * py[b];
  }
  for (int a = 0; a < 3; ++a) {
    *wy += (w[a][1] + w[a][2] * dy) * px[a];
    *wyy += w[a][2] * px[a];
  }
  *wxy = w[1][1] + w[2][1] * dx + w[1][2] * dy + w[2][2] * dx * dy;
}

void GriddedFluxMap::Derivatives(double id, double iq, double w[3][3]) const {
  const size_t ny = y_.size();
  const size_t i = Cell(x_, id), j = Cell(y_, iq);
  const double hx = x_[i + 1] - x_[i], hy = y_[j + 1] - y_[j];
  double fu[6][3], fv[6][3];
  Quintic((id - x_[i]) / hx, fu);
  Quintic((iq - y_[j]) / hy, fv);
  // W = sum over corners (a, b) and orders (p, q) of
  //   hx^p hy^q D[p][q](corner) H_{3a+p}(u) H_{3b+q}(v);
  // r[m][n] = d^(m+n) W / du^m dv^n.
  double r[3][3] = {};
  const double sx[3] = {1, hx, hx * hx}, sy[3] = {1, hy, hy * hy};
  for (int a = 0; a < 2; ++a) {
    for (int b = 0; b < 2; ++b) {
      const size_t n = (i + a) * ny + (j + b);
      for (int p = 0; p < 3; ++p) {
        for (int q = 0; q < 3; ++q) {
          const double c = d_[p][q][n] * sx[p] * sy[q];
          const double* U = fu[3 * a + p];
          const double* V = fv[3 * b + q];
          for (int mm = 0; mm < 3; ++mm) {
            for (int nn = 0; nn < 3; ++nn) r[mm][nn] += c * U[mm] * V[nn];
          }
        }
      }
    }
  }
  for (int mm = 0; mm < 3; ++mm) {
    for (int nn = 0; nn < 3; ++nn) w[mm][nn] = r[mm][nn] / (sx[mm] * sy[nn]);
  }
}

FluxLinkage GriddedFluxMap::Flux(double id, double iq, double temperature_c) const {
  // Symmetry: psi_d(id, -iq) = psi_d(id, iq), psi_q(id, -iq) = -psi_q(id, iq).
  const double s = iq < 0 ? -1.0 : 1.0;
  double wx, wy, a, b, c;
  Eval(id, s * iq, &wx, &wy, &a, &b, &c);
  return {wx + psi_pm_wb_ * temp_coeff_ * (temperature_c - 25.0), s * wy};
}

DifferentialInductance GriddedFluxMap::Inductance(double id, double iq, double) const {
  const double s = iq < 0 ? -1.0 : 1.0;
  double wx, wy, wxx, wyy, wxy;
  Eval(id, s * iq, &wx, &wy, &wxx, &wyy, &wxy);
  return {wxx, wyy, s * wxy};
}

}  // namespace fluxcal::sim
