// Fits of maps that bend like real machines, sampled the way an end-of-line
// bench reports them (6 x 6 differential inductances with 0.3 % noise, nine
// steady-state rows at speed with 0.3 % + 0.05 V voltage noise and 0.5 %
// torque noise, psi_pm from the map), over several noise draws:
//   - the measured map of a 5.6 kW PM-SyRM (data/real), whose
//     inductances come from the map's own central differences;
//   - synthetic maps with the traits of real ones (closed-form co-energies,
//     so the truth is exact): a PM-SyRM (small psi_pm, Lq >> Ld), an IPMSM
//     whose Lqq falls ~10x through the bridge knee and levels off, a map with
//     psi_q(id, 0) != 0, and a map with negative Ldd near zero current.
// The map with psi_q(id, 0) != 0 is not symmetric in iq: a bench measuring
// one half cannot tell it from a symmetric one (the fit then uses the
// machine's symmetry, docs/fitting.md), so it is sampled and judged on both
// halves here (BothHalves), and AsymmetricMachineOnOneHalf says what one
// half gives.
// The figure of merit is the issue's: RMS flux error over the map's nodes
// inside the sampled region, relative to the largest |psi| there.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <sstream>

#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "identification/identify.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "physics/hf_orbit.h"
#include "simulation/trait_motor.h"
#include "simulation/twin.h"

namespace fluxcal::fit {
namespace {

constexpr double kPi = std::numbers::pi;

// A flux map as a function: psi_d, psi_q at (id, iq).
using FluxFn = std::function<void(double id_a, double iq_a, double* psi_d_wb, double* psi_q_wb)>;

struct MachineMap {
  std::string name;
  FluxFn flux;          // truth used for the bench's observations
  FluxFn reference;     // what the fit is judged against (the raw map)
  double step_a = 0;    // central-difference step for the inductances
  double id_lo_a = 0, iq_hi_a = 0;   // sampled region: id in [id_lo, 0], iq in [0, iq_hi]
  std::vector<double> hf_id_a, hf_iq_a, ss_id_a, ss_iq_a;
  std::vector<double> eval_id_a, eval_iq_a;
  int pole_pairs = 2;
  double rs_ohm = 0, speed_rpm = 0;
};

// What an EOL bench reports for `m`, noise drawn with `seed`.
FitData EolDraw(const MachineMap& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  FitData d;
  d.serial = m.name;
  d.pole_pairs = m.pole_pairs;
  d.rs_ohm = m.rs_ohm;
  d.f_pwm_hz = 10000.0;
  double pm, pq0;
  m.flux(0, 0, &pm, &pq0);
  d.psi_pm_prior_wb = pm;
  const double h = m.step_a;
  for (double id : m.hf_id_a) {
    for (double iq : m.hf_iq_a) {
      double a[2], b[2], c[2], e[2];
      m.flux(id + h, iq, &a[0], &a[1]);
      m.flux(id - h, iq, &b[0], &b[1]);
      m.flux(id, iq + h, &c[0], &c[1]);
      m.flux(id, iq - h, &e[0], &e[1]);
      InductanceObservation o;
      o.id_a = id;
      o.iq_a = iq;
      o.ldd_h = (a[0] - b[0]) / (2 * h) * (1 + 0.003 * n01(rng));
      o.lqq_h = (c[1] - e[1]) / (2 * h) * (1 + 0.003 * n01(rng));
      o.ldq_h = 0.5 * ((c[0] - e[0]) + (a[1] - b[1])) / (2 * h) * (1 + 0.003 * n01(rng));
      d.inductances.push_back(o);
    }
  }
  const double we = m.speed_rpm * m.pole_pairs * 2 * kPi / 60.0;
  for (double id : m.ss_id_a) {
    for (double iq : m.ss_iq_a) {
      double pd, pq;
      m.flux(id, iq, &pd, &pq);
      const double ud = m.rs_ohm * id - we * pq, uq = m.rs_ohm * iq + we * pd;
      const double torque = 1.5 * m.pole_pairs * (pd * iq - pq * id);
      SteadyStateObservation s;
      s.id_a = id;
      s.iq_a = iq;
      s.speed_rpm = m.speed_rpm;
      s.ud_ref_v = ud * (1 + 0.003 * n01(rng)) + 0.05 * n01(rng);
      s.uq_ref_v = uq * (1 + 0.003 * n01(rng)) + 0.05 * n01(rng);
      s.torque_nm = torque * (1 + 0.005 * n01(rng));
      d.steady_state.push_back(s);
    }
  }
  return d;
}

// RMS flux error over the evaluation nodes, relative to the largest |psi|.
double FluxRms(const Calibration& cal, const MachineMap& m, double* max_rel = nullptr) {
  double sum = 0, scale = 0, worst = 0;
  int n = 0;
  for (double id : m.eval_id_a) {
    for (double iq : m.eval_iq_a) {
      double pd, pq;
      m.reference(id, iq, &pd, &pq);
      const auto f = cal.Flux(id, iq);
      const double e2 = std::pow(f.psi_d_wb - pd, 2) + std::pow(f.psi_q_wb - pq, 2);
      sum += e2;
      worst = std::max(worst, std::sqrt(e2));
      scale = std::max(scale, std::hypot(pd, pq));
      ++n;
    }
  }
  if (max_rel != nullptr) *max_rel = worst / scale;
  return std::sqrt(sum / n) / scale;
}

std::vector<double> Range(double lo, double hi, int n) {
  std::vector<double> v;
  for (int k = 0; k < n; ++k) v.push_back(lo + (hi - lo) * k / (n - 1));
  return v;
}

// ---- the measured PM-SyRM map -------------------------------------------

struct Grid {
  std::map<std::pair<int, int>, std::array<double, 4>> node;   // raw d, q, sym d, q
};

const Grid& Baldor() {
  static const Grid* g = [] {
    auto* g = new Grid;
    auto text = io::ReadFileToString(std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_fluxmap_measured.csv");
    EXPECT_TRUE(text.ok()) << "in-repo fixture: " << text.status();
    std::istringstream in(text.ok() ? *text : "");
    std::string line;
    std::getline(in, line);
    while (std::getline(in, line)) {
      double id, iq, a, b, c, e;
      if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf", &id, &iq, &a, &b, &c, &e) != 6) continue;
      g->node[{static_cast<int>(std::lround(id)), static_cast<int>(std::lround(iq))}] = {a, b, c, e};
    }
    return g;
  }();
  return *g;
}

MachineMap BaldorMachine() {
  MachineMap m;
  m.name = "baldor";
  auto at = [](int col) {
    return [col](double id, double iq, double* pd, double* pq) {
      const auto& v = Baldor().node.at({static_cast<int>(std::lround(id)), static_cast<int>(std::lround(iq))});
      *pd = v[col];
      *pq = v[col + 1];
    };
  };
  m.flux = at(2);        // the symmetrised map, as the bench file's inductances
  m.reference = at(0);   // judged against the raw measured map
  m.step_a = 2.0;
  m.hf_id_a = {-18, -14, -10, -8, -4, 0};
  m.hf_iq_a = {0, 4, 10, 14, 20, 24};
  m.ss_id_a = {-18, -10, -4};
  m.ss_iq_a = {4, 14, 24};
  m.eval_id_a = Range(-18, 0, 10);
  m.eval_iq_a = Range(0, 24, 13);
  m.pole_pairs = 2;
  m.rs_ohm = 3.6;
  m.speed_rpm = 400;
  return m;
}

// ---- twin motors with real traits (simulation/trait_motor.h) ----------

MachineMap TraitMachine(const sim::MotorTraits& t, double imax_a) {
  auto motor = std::make_shared<sim::TraitMotor>(t);
  MachineMap m;
  m.name = t.name;
  m.flux = [motor](double id, double iq, double* pd, double* pq) {
    const auto f = motor->Flux(id, iq);
    *pd = f.psi_d_wb;
    *pq = f.psi_q_wb;
  };
  m.reference = m.flux;
  m.step_a = 1e-4 * imax_a;
  m.hf_id_a = {-imax_a, -0.75 * imax_a, -0.55 * imax_a, -0.45 * imax_a, -0.2 * imax_a, 0};
  m.hf_iq_a = {0, 0.17 * imax_a, 0.42 * imax_a, 0.58 * imax_a, 0.83 * imax_a, imax_a};
  m.ss_id_a = {-imax_a, -0.55 * imax_a, -0.2 * imax_a};
  m.ss_iq_a = {0.17 * imax_a, 0.58 * imax_a, imax_a};
  m.eval_id_a = Range(-imax_a, 0, 13);
  m.eval_iq_a = Range(0, imax_a, 13);
  m.pole_pairs = 4;
  m.rs_ohm = 0.02;
  m.speed_rpm = 1000;
  return m;
}

// `m` sampled and judged on both halves of the iq axis: what a bench does
// for a machine that is not symmetric in iq. Its iq levels, steady-state
// rows and evaluation nodes up to kMirroredShare of the largest iq are
// mirrored (iq -> -iq): the trait maps were made for iq >= 0, and the
// psi_q(id, 0) one is not positive definite at its far negative corner
// (det L < 0 at id = iq = -300 A on its 300 A scale), which no physical fit
// follows.
constexpr double kMirroredShare = 0.6;
MachineMap BothHalves(MachineMap m) {
  auto mirror = [](std::vector<double> v) {
    const size_t n = v.size();
    const double top = *std::max_element(v.begin(), v.end());
    for (size_t k = 0; k < n; ++k) {
      if (v[k] > 0 && v[k] <= kMirroredShare * top * (1 + 1e-9)) v.push_back(-v[k]);
    }
    std::sort(v.begin(), v.end());
    return v;
  };
  m.hf_iq_a = mirror(m.hf_iq_a);
  m.ss_iq_a = mirror(m.ss_iq_a);
  m.eval_iq_a = mirror(m.eval_iq_a);
  return m;
}

std::vector<MachineMap> Machines() {
  std::vector<MachineMap> v;
  v.push_back(BaldorMachine());
  // Each trait motor at the current range it was stated for; the one not
  // symmetric in iq on both halves.
  const double imax[] = {200, 400, 300, 300};
  for (int k = 0; k < 4; ++k) {
    const auto t = sim::RealLikeMotors(imax[k])[k];
    v.push_back(t.psi_q_offset_wb != 0 ? BothHalves(TraitMachine(t, imax[k])) : TraitMachine(t, imax[k]));
  }
  return v;
}

// Bench draws `first_seed`.. of `m` fitted with `--model auto`: mean and
// worst RMS flux error, draws above 0.5 %, the families chosen; `each` sees
// every calibration and its error (a failed fit is a test failure).
struct Draws {
  double mean = 0, worst = 0;
  int above = 0;
  std::string families;
};
Draws FitDraws(const MachineMap& m, unsigned first_seed, unsigned count,
               const std::function<void(const Calibration&, unsigned seed, double rms)>& each = {}) {
  Draws r;
  for (unsigned seed = first_seed; seed < first_seed + count; ++seed) {
    auto cal = Fit(EolDraw(m, seed), {});
    EXPECT_TRUE(cal.ok()) << m.name << " seed " << seed << ": " << cal.status();
    if (!cal.ok()) continue;
    const double rms = FluxRms(*cal, m);
    r.worst = std::max(r.worst, rms);
    r.mean += rms / count;
    r.above += rms > 0.005;
    r.families += cal->family().Name() + " ";
    if (each) each(*cal, seed, rms);
  }
  return r;
}

// Five noise draws per machine, `--model auto`: every draw within the
// issue's 0.5 % RMS (and on 20 more draws, TwentyMoreDraws). On the map with
// negative Ldd near zero current the non-positive point is excluded and
// listed with the cells around it where the surface is not required
// positive definite; required there too, every smoothing spline that
// followed the neighbours into the dip was vetoed and a 4-span spline was
// left, 0.67 % off.
TEST(RealMaps, FluxErrorOnEveryDraw) {
  for (const auto& m : Machines()) {
    const Draws d = FitDraws(m, 1, 5, [&](const Calibration& cal, unsigned, double) {
      if (m.name != "negative-slope") return;
      bool listed = false;
      for (const auto& e : cal.summary.excluded) {
        listed |= e.find("ldd_h") != std::string::npos && e.find("not required positive definite") != std::string::npos;
      }
      EXPECT_TRUE(listed) << "the non-positive Ldd point and its cells are not listed as excluded";
    });
    std::printf("%-15s mean %.3f %% worst %.3f %%  [%s]\n", m.name.c_str(), 100 * d.mean, 100 * d.worst,
                d.families.c_str());
    EXPECT_LT(d.worst, 0.005) << m.name;
  }
}

// A trait motor end to end through the twin: the default plan's HF
// injection recording (id -100..0 A, iq 0..100 A) simulated, identified
// and fitted; flux over the plan's region against the motor. Flux scaled
// to the default twin motor's level (~0.05 Wb at 100 A, `flux_scale` 0.15
// of the traits), so the plan's steady-state speeds stay inside the
// inverter's voltage.
struct EndToEnd {
  bool ok = false;
  int failed = 0;   // points the identification reports failed
  std::string family;
  double rms = 1, max = 1;
};
// The default plan (iq 0..100 A) with every point and row of 0 < iq <=
// kMirroredShare x 100 A repeated at -iq: a bench for a machine that is not
// symmetric in iq (BothHalves).
sim::Plan BothHalvesPlan() {
  sim::Plan p = sim::DefaultPlan();
  const size_t n = p.points.size(), m = p.steady_state.size();
  const double top = kMirroredShare * 100.0 * (1 + 1e-9);
  for (size_t k = 0; k < n; ++k) {
    if (p.points[k].iq_ref_a <= 0 || p.points[k].iq_ref_a > top) continue;
    sim::PlanPoint q = p.points[k];
    q.id += "n";
    q.iq_ref_a = -q.iq_ref_a;
    p.points.push_back(q);
  }
  for (size_t k = 0; k < m; ++k) {
    if (p.steady_state[k].iq_ref_a <= 0 || p.steady_state[k].iq_ref_a > top) continue;
    sim::PlanSteadyState q = p.steady_state[k];
    q.iq_ref_a = -q.iq_ref_a;
    p.steady_state.push_back(q);
  }
  return p;
}

// A trait motor not symmetric in iq (psi_q(id, 0) != 0) runs the plan on
// both halves and is judged on both (BothHalves).
bool Asymmetric(const sim::MotorTraits& t) { return t.psi_q_offset_wb != 0; }

// The twin's bench on trait motor `t`: its magnet flux and magnetics, the
// controller tuned from them when `gain_scheduled`, noise drawn with `seed`.
sim::TwinConfig TraitTwin(const sim::MotorTraits& t, int seed, bool gain_scheduled) {
  sim::TwinConfig cfg;
  cfg.seed = seed;
  cfg.serial = "TRAIT-" + t.name;
  cfg.motor.sat.psi_pm_wb = t.psi_pm_wb;
  cfg.magnetics = std::make_shared<sim::TraitMotor>(t);
  cfg.control.gain_scheduled = gain_scheduled;
  return cfg;
}

EndToEnd TwinEndToEnd(const sim::MotorTraits& t, int seed, bool gain_scheduled) {
  EndToEnd e;
  const sim::TwinConfig cfg = TraitTwin(t, seed, gain_scheduled);
  auto r = sim::Simulate(cfg, Asymmetric(t) ? BothHalvesPlan() : sim::DefaultPlan());
  EXPECT_TRUE(r.ok()) << t.name << ": " << r.status();
  if (!r.ok()) return e;
  auto ids = ident::IdentifySet(r->set, {});
  EXPECT_TRUE(ids.ok()) << t.name << ": " << ids.status();
  if (!ids.ok()) return e;
  for (const auto& p : *ids) e.failed += !p.failure.empty();
  auto cal = Fit(FitDataFromRecording(r->set, *ids), {});
  EXPECT_TRUE(cal.ok()) << t.name << ": " << cal.status();
  if (!cal.ok()) return e;
  e.ok = true;
  e.family = cal->family().Name();
  e.rms = FluxRms(*cal, Asymmetric(t) ? BothHalves(TraitMachine(t, 100.0)) : TraitMachine(t, 100.0), &e.max);
  return e;
}

// The trait motors on a bench whose controller is tuned from the motor's
// own magnetics (control.gain_scheduled, docs/simulation.md), as a bench
// for such a machine is; three noise draws.
TEST(RealMaps, TwinTraitMotorsEndToEnd) {
  for (int seed : {31, 32, 33}) {
    for (const auto& t : sim::RealLikeMotors(100.0, 0.15)) {
      const EndToEnd e = TwinEndToEnd(t, seed, true);
      ASSERT_TRUE(e.ok) << t.name;
      std::printf("twin seed %d %-14s %-12s flux RMS %.3f %% max %.3f %%\n", seed, t.name.c_str(), e.family.c_str(),
                  100 * e.rms, 100 * e.max);
      // ipm-bridge: 0.52-0.57 % (allowed 0.6 %) until the identification
      // read the bench's negative-sequence command (docs/identification.md,
      // Sec. 8); 0.25-0.35 % since.
      EXPECT_LT(e.rms, 0.005) << t.name << " seed " << seed;
    }
  }
}

// The machines of other kinds (sim::OtherKindMotors: synchronous
// reluctance, surface magnet, strong cross saturation, deep saturation in
// both axes) end to end through the twin on a bench tuned for each
// (control.gain_scheduled): the 1 % for machines the fit was not
// developed on. On the last two the bench's decoupled PI pair still runs
// into the voltage limit at the high-current points (9-13 of 40; not
// analysed further): the identification reports them failed, the fit uses
// the rest, and the flux over the whole box is 0.39 % and 0.88-0.92 %.
TEST(RealMaps, OtherKindsEndToEnd) {
  for (int seed : {41, 42}) {
    for (const auto& t : sim::OtherKindMotors(100.0, 0.15)) {
      const EndToEnd e = TwinEndToEnd(t, seed, true);
      ASSERT_TRUE(e.ok) << t.name;
      std::printf("other kind, twin seed %d %-13s %d failed, %-12s flux RMS %.3f %% max %.3f %%\n", seed,
                  t.name.c_str(), e.failed, e.family.c_str(), 100 * e.rms, 100 * e.max);
      EXPECT_LT(e.rms, 0.01) << t.name << " seed " << seed;
    }
  }
}

// The same motors on a bench whose fixed gains were tuned for the default
// motor (0.18 / 0.35 mH): on the bridge-knee and negative-slope maps the
// q loop oscillates into the voltage limit at 6-7 of 40 locked points and
// at speed. What fluxcal gets is then a set with failed points and rows
// that averaged a limit cycle, which the bench reports not held (at the
// voltage limit, rippled) and the fit leaves out or down-weights. Nothing
// aborts, the failed points are reported, and the fit stays bounded: 1.4 %
// and 0.5 % (the other two motors 0.46 % and 0.23 %).
TEST(RealMaps, TwinTraitMotorsOnAMistunedBench) {
  for (const auto& t : sim::RealLikeMotors(100.0, 0.15)) {
    const EndToEnd e = TwinEndToEnd(t, 31, false);
    ASSERT_TRUE(e.ok) << t.name;
    std::printf("mistuned bench %-14s %d points failed, %-12s flux RMS %.3f %% max %.3f %%\n", t.name.c_str(),
                e.failed, e.family.c_str(), 100 * e.rms, 100 * e.max);
    // pm-syrm: 0.26 % before the twin wrote what its bench held per row
    // (a row at the voltage limit for 30 % of its window, 0.2 % off, is
    // now excluded: 0.46 %), 0.57 % with the likelihood's smoothing on top
    // (docs/fitting.md): bounded like the negative-slope map.
    const double bound = t.name == "ipm-bridge" ? 0.035 : t.name != "psi-q-offset" ? 0.008 : 0.005;
    EXPECT_LT(e.rms, bound) << t.name;
  }
}

// The synchronous reluctance machine on the fixed-gain bench (seed 41):
// 4 of its 8 steady-state rows (1500-2000 rpm, 52-100 A) read psi_q 3-7 %
// low but agree with their own torque, and with it they outweighed the
// iq = 0 HF row: 19.8 % off. The twin writes what its bench held per row
// (docs/recording-format.md, "Rows a bench could not hold"): those rows sat
// at the voltage limit for 46-69 % of their window and are excluded, a row
// rippled by 22 % of its current is down-weighted (docs/fitting.md): 0.91 %
// with GCV's smoothing, 1.14 % with the likelihood's (its weight and
// anisotropy, docs/fitting.md); without the ripple's widening 0.96 % (the
// widening's curvature bound is 3-10x loose on these machines: estimating
// the curvature from the surface is the open step). Asserted: within 1.5 %,
// against 19.8 % before.
TEST(RealMaps, SelfConsistentBadRowsOnAMistunedBench) {
  for (const auto& t : sim::OtherKindMotors(100.0, 0.15)) {
    if (t.name != "syrm") continue;
    const EndToEnd e = TwinEndToEnd(t, 41, false);
    ASSERT_TRUE(e.ok);
    std::printf("mistuned bench %-13s %d failed, %-12s flux RMS %.3f %% max %.3f %%\n", t.name.c_str(), e.failed,
                e.family.c_str(), 100 * e.rms, 100 * e.max);
    EXPECT_LT(e.rms, 0.015);
  }
}

// The fitted self inductances against the machine's over the default
// plan's box (id -100..0 A, iq 0..100 A, 10 A steps): RMS relative error of
// Ldd and Lqq together.
double InductanceRmsOverPlan(const Calibration& cal, const sim::TraitMotor& machine) {
  double e = 0;
  int m = 0;
  for (double id = -100; id <= 0; id += 10) {
    for (double iq = 0; iq <= 100; iq += 10) {
      const auto a = cal.Inductance(id, iq), b = machine.Inductance(id, iq);
      e += std::pow(a.ldd_h / b.ldd_h - 1, 2) + std::pow(a.lqq_h / b.lqq_h - 1, 2);
      m += 2;
    }
  }
  return std::sqrt(e / m);
}

// Large-signal HF (physics/hf_orbit.h, docs/fitting.md): the default
// injection (5 V at 500 Hz, a flux circle of 1.6 mWb) drives the current of
// these machines over 10-50 A about each point, across the saturation
// knees. What the identification reports is the describing function over
// that orbit, not the Jacobian at the point's mean current: on the bridge
// knee and on the reluctance machine's d-axis knee the identified values
// sit 5-15 of the fit's sigmas off the machine's small-signal ones (chi^2
// 215 and 21 per point) and at about the sigma of its describing function
// (1.6, 1.6). The fit that predicts the points so (FitOptions::large_signal_hf,
// the default) gets the bridge machine's inductances over the box closer,
// 3.5 -> 1.5 % RMS, and the reluctance machine's no worse, 1.20 -> 1.20 %
// (its flux 0.49 -> 0.30 %, LargeSignalTable). (3.9 -> 1.0 % and 1.4 ->
// 0.8 % while the identification took the bench's negative-sequence
// command as zero, docs/identification.md, Sec. 8, and its standard errors
// from the residual's mean power, Sec. 5.) The other machines, where it is
// not always better, are in LargeSignalTable; the flux error in
// TwinTraitMotorsEndToEnd and OtherKindsEndToEnd.
TEST(RealMaps, LargeSignalHfIsWhatTheInjectionMeasures) {
  std::vector<sim::MotorTraits> motors;
  for (const auto& t : sim::RealLikeMotors(100.0, 0.15)) if (t.name == "ipm-bridge") motors.push_back(t);
  for (const auto& t : sim::OtherKindMotors(100.0, 0.15)) if (t.name == "syrm") motors.push_back(t);
  ASSERT_EQ(motors.size(), 2u);
  for (const auto& t : motors) {
    const sim::TwinConfig cfg = TraitTwin(t, 31, true);
    const auto machine = std::static_pointer_cast<const sim::TraitMotor>(cfg.magnetics);
    auto r = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(r.ok()) << r.status();
    auto ids = ident::IdentifySet(r->set, {});
    ASSERT_TRUE(ids.ok()) << ids.status();
    const FitData data = FitDataFromRecording(r->set, *ids);
    // The identified values against the machine's small-signal and
    // describing-function values: chi^2 per point of the worse axis.
    auto map = [&](double id, double iq, double* psi, double* l) {
      const auto f = machine->Flux(id, iq);
      const auto L = machine->Inductance(id, iq);
      psi[0] = f.psi_d_wb; psi[1] = f.psi_q_wb;
      l[0] = L.ldd_h; l[1] = L.lqq_h; l[2] = L.ldq_h;
    };
    double chi2_small = 0, chi2_large = 0;
    int n = 0;
    for (const auto& o : data.inductances) {
      ASSERT_TRUE(o.hf_flux_radius_wb.has_value());
      std::vector<std::array<double, 2>> orbit;
      std::array<std::vector<std::array<double, 2>>, 3> w;
      if (!physics::HfOrbit(map, o.id_a, o.iq_a, *o.hf_flux_radius_wb, &orbit) ||
          !physics::DescribingWeights(orbit, &w)) {
        continue;
      }
      double large[2] = {0, 0};
      for (size_t k = 0; k < orbit.size(); ++k) {
        double psi[2], l[3];
        map(orbit[k][0], orbit[k][1], psi, l);
        for (int c = 0; c < 2; ++c) large[c] += w[c][k][0] * psi[0] + w[c][k][1] * psi[1];
      }
      const auto small = machine->Inductance(o.id_a, o.iq_a);
      // The sigmas the fit weighs the points with: the standard error, at
      // least the identification's systematic 0.2 % (FitOptions).
      const double sd = std::max(o.ldd_h_std, FitOptions{}.relative_sigma_floor * o.ldd_h);
      const double sq = std::max(o.lqq_h_std, FitOptions{}.relative_sigma_floor * o.lqq_h);
      chi2_small += std::max(std::pow((o.ldd_h - small.ldd_h) / sd, 2), std::pow((o.lqq_h - small.lqq_h) / sq, 2));
      chi2_large += std::max(std::pow((o.ldd_h - large[0]) / sd, 2), std::pow((o.lqq_h - large[1]) / sq, 2));
      ++n;
    }
    ASSERT_GE(n, 30) << t.name;
    // The fitted inductances against the machine's over the plan's box.
    FitOptions small_signal;
    small_signal.large_signal_hf = false;
    auto cal_small = Fit(data, small_signal);
    auto cal_large = Fit(data, {});
    ASSERT_TRUE(cal_small.ok() && cal_large.ok()) << t.name;
    const double e_small = InductanceRmsOverPlan(*cal_small, *machine);
    const double e_large = InductanceRmsOverPlan(*cal_large, *machine);
    std::printf("%-10s chi2 per point: small-signal %.1f, describing %.2f; inductance RMS small-signal fit %.2f %%, "
                "large-signal fit %.2f %%\n",
                t.name.c_str(), chi2_small / n, chi2_large / n, 100 * e_small, 100 * e_large);
    // The calibration says which HF model it kept (fit.cc, the score).
    ASSERT_FALSE(cal_large->summary.candidates.empty());
    EXPECT_NE(cal_large->summary.candidates.back().find("large-signal kept"), std::string::npos)
        << cal_large->summary.candidates.back();
    EXPECT_GT(chi2_small / n, 10.0) << t.name;
    EXPECT_LT(chi2_large / n, 3.0) << t.name;
    EXPECT_LT(e_large, 1.05 * e_small) << t.name;
    // On the bridge knee clearly better: 1.34 % against 1.85 % since the
    // bench starts each point on the injection's orbit (1.51 against 3.46 %
    // before: the start's flux step, still decaying in the window, bent
    // the small-signal fit more; docs/simulation.md).
    if (t.name == "ipm-bridge") EXPECT_LT(e_large, 0.8 * e_small);
  }
}

// The table of docs/fitting.md, "Large-signal HF", made by one command
// (`fitting_test --gtest_filter='RealMaps.LargeSignalTable'`): per set the
// cross-validation score of the small- and the large-signal fit, which one
// the calibration keeps, and both fits' flux and inductance errors (twin
// machines over the plan's box; example sets at their truth file's
// points). Asserted: the gate's decision as the docs state it, the knee
// machines keep the large-signal model, the sets whose identified values
// match the machine's Jacobians (the independent examples, the measured
// machine's bench, the twin's default motor) keep the small-signal one.
// The example sets live beside the repository; without them only the twin
// rows run.
struct GateRow {
  double cv_small = 0, cv_large = 0, median_sigmas = 0;
  bool large_kept = false;
};
// Scores from the calibration's candidate line ("hf model: ..., median
// change M sigma) cv=A, small-signal cv=B: X kept"); no line: no orbit
// mattered (small kept).
GateRow GateOf(const Calibration& cal) {
  GateRow g;
  for (const auto& line : cal.summary.candidates) {
    if (line.rfind("hf model:", 0) != 0) continue;
    std::sscanf(line.c_str() + line.find(") cv=") + 5, "%lf", &g.cv_large);
    std::sscanf(line.c_str() + line.find("small-signal cv=") + 16, "%lf", &g.cv_small);
    std::sscanf(line.c_str() + line.find("median change ") + 14, "%lf", &g.median_sigmas);
    g.large_kept = line.find("large-signal kept") != std::string::npos;
  }
  return g;
}
TEST(RealMaps, LargeSignalTable) {
  struct Twin { std::string name; bool knee; };
  std::vector<sim::MotorTraits> motors = sim::RealLikeMotors(100.0, 0.15);
  for (const auto& t : sim::OtherKindMotors(100.0, 0.15)) motors.push_back(t);
  for (const auto& t : motors) {
    if (Asymmetric(t) || t.name == "spm") continue;   // judged on both halves elsewhere; spm has no knee
    const sim::TwinConfig cfg =
        TraitTwin(t, t.name == "syrm" || t.name == "deep-sat" || t.name == "strong-cross" ? 41 : 31, true);
    const auto machine = std::static_pointer_cast<const sim::TraitMotor>(cfg.magnetics);
    auto r = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(r.ok()) << r.status();
    auto ids = ident::IdentifySet(r->set, {});
    ASSERT_TRUE(ids.ok());
    const FitData data = FitDataFromRecording(r->set, *ids);
    FitOptions small;
    small.large_signal_hf = false;
    auto cs = Fit(data, small);
    auto cl = Fit(data, {});
    ASSERT_TRUE(cs.ok() && cl.ok()) << t.name;
    const GateRow g = GateOf(*cl);
    const MachineMap mm = TraitMachine(t, 100.0);
    std::printf("twin %-14s seed %d | median %.2g sigma | cv small %.4g large %.4g | %s kept | flux %.3f / %.3f %% | "
                "L %.2f / %.2f %%\n",
                t.name.c_str(), static_cast<int>(cfg.seed), g.median_sigmas, g.cv_small, g.cv_large,
                g.large_kept ? "large" : "small",
                100 * FluxRms(*cs, mm), 100 * FluxRms(*cl, mm), 100 * InductanceRmsOverPlan(*cs, *machine),
                100 * InductanceRmsOverPlan(*cl, *machine));
    EXPECT_TRUE(g.large_kept) << t.name;
  }
  {
    sim::TwinConfig cfg;
    cfg.seed = 1;
    cfg.serial = "IPM-DEFAULT";
    auto r = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(r.ok());
    auto ids = ident::IdentifySet(r->set, {});
    ASSERT_TRUE(ids.ok());
    auto cl = Fit(FitDataFromRecording(r->set, *ids), {});
    ASSERT_TRUE(cl.ok());
    const GateRow g = GateOf(*cl);
    std::printf("twin default motor seed 1 | cv small %.4g large %.4g | %s kept\n", g.cv_small, g.cv_large,
                g.large_kept ? "large" : "small");
    EXPECT_FALSE(g.large_kept);
  }
  for (const char* name : {"clean", "cross_saturation", "real/baldor_bench_clean"}) {
    const std::filesystem::path root = std::filesystem::path(FLUXCAL_SHARED_DIR) / "examples";
    if (!std::filesystem::exists(root / name / "manifest.json") ||
        !std::filesystem::exists(root / (std::string(name) + ".truth.json"))) {
      std::printf("example %s: skipped (../shared/examples not beside the repository)\n", name);
      continue;
    }
    auto set = io::ReadRecordingSet((root / name).string());
    ASSERT_TRUE(set.ok()) << set.status();
    auto ids = ident::IdentifySet(*set, {});
    ASSERT_TRUE(ids.ok());
    const FitData data = FitDataFromRecording(*set, *ids);
    FitOptions small;
    small.large_signal_hf = false;
    auto cs = Fit(data, small);
    auto cl = Fit(data, {});
    ASSERT_TRUE(cs.ok() && cl.ok()) << name;
    std::ifstream f(root / (std::string(name) + ".truth.json"));
    const auto truth = nlohmann::json::parse(f);
    auto errors = [&](const Calibration& c, double* flux, double* l) {
      double ef = 0, el = 0, scale = 0;
      int n = 0;
      for (const char* key : {"points", "steady_state"}) {
        for (const auto& p : truth[key]) {
          const double id = p["id_true_a"], iq = p["iq_true_a"];
          const auto fl = c.Flux(id, iq);
          const double pd = p["psi_d_wb"], pq = p["psi_q_wb"];
          ef += std::pow(fl.psi_d_wb - pd, 2) + std::pow(fl.psi_q_wb - pq, 2);
          scale = std::max(scale, std::hypot(pd, pq));
          const auto L = c.Inductance(id, iq);
          el += std::pow(L.ldd_h / p["ldd_h"].get<double>() - 1, 2) + std::pow(L.lqq_h / p["lqq_h"].get<double>() - 1, 2);
          ++n;
        }
      }
      *flux = std::sqrt(ef / n) / scale;
      *l = std::sqrt(el / (2 * n));
    };
    double fs, ls;
    errors(*cs, &fs, &ls);
    const GateRow g = GateOf(*cl);
    std::printf("example %-24s | median %.2g sigma | cv small %.4g large %.4g | %s kept | flux %.3f %% | L %.3f %% "
                "(kept fit)\n",
                name, g.median_sigmas, g.cv_small, g.cv_large, g.large_kept ? "large" : "small", 100 * fs, 100 * ls);
    EXPECT_FALSE(g.large_kept) << name;
  }
}

// A coarse, exact flux map (each machine's 6 x 6 bench grid of flux nodes,
// no noise, nothing else), as `fluxcal fit --map` gets from a coarse FEA
// export: 72 observations for a spline of 121-145 coefficients. GCV's
// near-interpolation basin (RSS ~ 0, n - tr(H) of 2 of 84) once won here
// and the surface wiggled between the nodes (7 % off in the MTPA table of
// the independent example's truth points); the fit keeps 10 % of the
// observations as residual degrees of freedom. Flux within 1 % RMS.
TEST(RealMaps, CoarseExactFluxMap) {
  for (const auto& m : Machines()) {
    if (m.name == "negative-slope") continue;   // its non-positive region is what the bench grid cannot see
    FitData d;
    d.serial = m.name;
    d.pole_pairs = m.pole_pairs;
    double psi_max = 0;
    for (double id : m.hf_id_a) {
      for (double iq : m.hf_iq_a) {
        double pd, pq;
        m.flux(id, iq, &pd, &pq);
        psi_max = std::max(psi_max, std::hypot(pd, pq));
        d.fluxes.push_back({id, iq, pd, pq, 0.0});
      }
    }
    for (auto& f : d.fluxes) f.psi_std_wb = 1e-4 * psi_max;
    auto cal = Fit(d, {});
    ASSERT_TRUE(cal.ok()) << m.name << ": " << cal.status();
    const double rms = FluxRms(*cal, m);
    std::printf("%-14s coarse exact flux map (%zu nodes): %-12s flux RMS %.3f %%\n", m.name.c_str(), d.fluxes.size(),
                cal->family().Name().c_str(), 100 * rms);
    EXPECT_LT(rms, 0.01) << m.name;
  }
}

// What a bench may leave out: no Ldq column, another grid, no steady-state
// rows (HF results alone). Three draws each, worst RMS flux error printed;
// asserted where the fit is expected to hold (docs/fitting.md): without Ldq
// below 0.6 %, on another grid of the measured map below 0.8 %, and HF
// results alone below 2 % (their flux is the integral of an interpolated
// inductance: 0.1-1.5 % on these maps, said in the docs).
TEST(RealMaps, WhatTheBenchLeavesOut) {
  for (const auto& m0 : Machines()) {
    for (int var = 0; var < 4; ++var) {
      MachineMap m = m0;
      if (var == 3) {
        if (m.name != "baldor") continue;
        m.hf_id_a = {-18, -12, -6, 0};
        m.hf_iq_a = {0, 2, 6, 12, 18, 24};
      }
      if (var == 0) continue;   // as-is: FluxErrorOnEveryDraw
      double worst = 0;
      std::string fam;
      for (unsigned seed = 1; seed <= 3; ++seed) {
        FitData d = EolDraw(m, seed);
        if (var == 1) d.steady_state.clear();
        if (var == 2)
          for (auto& o : d.inductances) o.ldq_h.reset();
        auto cal = Fit(d, {});
        ASSERT_TRUE(cal.ok()) << m.name << " variant " << var << ": " << cal.status();
        worst = std::max(worst, FluxRms(*cal, m));
        fam += cal->family().Name() + " ";
      }
      const char* names[] = {"as-is", "HF results alone", "no Ldq", "other grid"};
      std::printf("%-15s %-17s worst %.3f %% [%s]\n", m.name.c_str(), names[var], 100 * worst, fam.c_str());
      if (var == 1) {
        EXPECT_LT(worst, 0.02) << m.name;   // 5.1 % on the PM-SyRM map with Cauchy's loss
      }
      if (var == 2) {
        EXPECT_LT(worst, 0.006) << m.name;
      }
      if (var == 3) {
        EXPECT_LT(worst, 0.008) << m.name;
      }
    }
  }
}


// The fitted differential inductances against the map's own (central
// differences of the map the bench sampled), five bench draws per map:
// RMS error of each component relative to its largest value over the
// evaluation nodes, and the slope sign changes of Ldd along id, Lqq along
// iq and Ldq along both (summed over the grid lines) against the map's.
// A controller tuned from these inductances (current-loop gains,
// observers) inherits every wiggle. With lambda from GCV's basins and one
// isotropic weight the measured map's fit had 112 sign changes per draw
// (the map 35) and Ldd 2.1 % RMS. Asserted: each component within 2 % RMS
// of the map's on every map, and at most `most` sign changes per draw (a few
// above docs/fitting.md's, "The inductance's curvature in the penalty").
int SlopeSignChanges(const std::vector<double>& v) {
  int c = 0;
  for (size_t i = 2; i < v.size(); ++i) c += (v[i] - v[i - 1]) * (v[i - 1] - v[i - 2]) < 0;
  return c;
}
TEST(RealMaps, InductancesAsSmoothAsTheMachine) {
  for (const auto& m : Machines()) {
    const double h = m.step_a;
    auto map_l = [&](double id, double iq, int k) {
      double a[2], b[2], c[2], e[2];
      m.flux(id + h, iq, &a[0], &a[1]);
      m.flux(id - h, iq, &b[0], &b[1]);
      m.flux(id, iq + h, &c[0], &c[1]);
      m.flux(id, iq - h, &e[0], &e[1]);
      if (k == 0) return (a[0] - b[0]) / (2 * h);
      if (k == 1) return (c[1] - e[1]) / (2 * h);
      return 0.5 * ((c[0] - e[0]) + (a[1] - b[1])) / (2 * h);
    };
    auto fit_l = [](const Calibration& cal, double id, double iq, int k) {
      const auto x = cal.Inductance(id, iq);
      return k == 0 ? x.ldd_h : k == 1 ? x.lqq_h : x.ldq_h;
    };
    // (component, along id?) of the four slope counts.
    const int comp[4] = {0, 1, 2, 2};
    const bool along_id[4] = {true, false, true, false};
    auto sign_changes = [&](const std::function<double(double, double, int)>& l, int q) {
      int total = 0;
      for (double o : along_id[q] ? m.eval_iq_a : m.eval_id_a) {
        std::vector<double> v;
        for (double x : along_id[q] ? m.eval_id_a : m.eval_iq_a) {
          v.push_back(along_id[q] ? l(x, o, comp[q]) : l(o, x, comp[q]));
        }
        total += SlopeSignChanges(v);
      }
      return total;
    };
    int map_changes = 0;
    for (int q = 0; q < 4; ++q) map_changes += sign_changes(map_l, q);
    double worst_rms[3] = {0, 0, 0}, mean_changes = 0;
    constexpr int kDraws = 5;
    for (unsigned seed = 1; seed <= kDraws; ++seed) {
      auto cal = Fit(EolDraw(m, seed), {});
      ASSERT_TRUE(cal.ok()) << m.name << ": " << cal.status();
      double se[3] = {0, 0, 0}, top[3] = {0, 0, 0};
      int n = 0;
      for (double id : m.eval_id_a) {
        for (double iq : m.eval_iq_a) {
          for (int k = 0; k < 3; ++k) se[k] += std::pow(map_l(id, iq, k) - fit_l(*cal, id, iq, k), 2);
          top[0] = std::max(top[0], std::abs(map_l(id, iq, 0)));
          top[1] = std::max(top[1], std::abs(map_l(id, iq, 1)));
          ++n;
        }
      }
      top[2] = std::max(top[0], top[1]);   // Ldq relative to the larger self inductance
      for (int k = 0; k < 3; ++k) worst_rms[k] = std::max(worst_rms[k], std::sqrt(se[k] / n) / top[k]);
      const auto l = [&](double id, double iq, int k) { return fit_l(*cal, id, iq, k); };
      for (int q = 0; q < 4; ++q) mean_changes += sign_changes(l, q) / double(kDraws);
    }
    std::printf("%-15s inductance RMS (worst draw) Ldd %.2f %% Lqq %.2f %% Ldq %.2f %%, slope sign changes map %d, "
                "fit %.1f per draw\n",
                m.name.c_str(), 100 * worst_rms[0], 100 * worst_rms[1], 100 * worst_rms[2], map_changes, mean_changes);
    for (int k = 0; k < 3; ++k) EXPECT_LT(worst_rms[k], 0.02) << m.name << " component " << k;
    const std::map<std::string, double> most = {
        {"baldor", 47}, {"pm-syrm", 43}, {"ipm-bridge", 75}, {"psi-q-offset", 44}, {"negative-slope", 60}};
    EXPECT_LE(mean_changes, most.at(m.name)) << m.name << ": the fitted inductances wiggle again";
  }
}

// Twenty more noise draws of every map (seeds 100-119), the issue's "any
// noise draw": every draw within 0.5 % RMS. Before the restricted
// likelihood chose lambda and the anisotropy of the penalty (fitting/
// select.cc, solve_linear.cc) one draw of the bridge-knee map was at
// 0.501 % and one of the negative-slope map at 0.83 % (the likelihood then
// only chose among GCV's basins); earlier still 2 of the measured map's 20
// were above 0.5 % (worst 0.95 %). Figures in docs/fitting.md.
TEST(RealMaps, TwentyMoreDraws) {
  for (const auto& m : Machines()) {
    const Draws d = FitDraws(m, 100, 20, [&](const Calibration&, unsigned seed, double rms) {
      EXPECT_LT(rms, 0.005) << m.name << " seed " << seed;
    });
    std::printf("%-15s 20 draws: mean %.3f %%, worst %.3f %%, %d above 0.5 %%\n", m.name.c_str(), 100 * d.mean,
                100 * d.worst, d.above);
  }
}

// Machines of kinds the fit was not developed on (sim::OtherKindMotors):
// a synchronous reluctance machine without magnet (psi_pm = 0: its prior
// once had a zero sigma, the analytic family's residual became 0/0 and the
// covariance crashed the process), a surface-magnet machine, strong cross
// saturation, deep saturation in both axes. Ten bench draws each, every
// draw within 0.5 % (one synchronous reluctance draw was at 0.51 % before
// the likelihood chose the penalty's weight and anisotropy,
// docs/fitting.md).
TEST(RealMaps, OtherKinds) {
  const double imax[] = {200, 300, 300, 300};
  for (int k = 0; k < 4; ++k) {
    const MachineMap m = TraitMachine(sim::OtherKindMotors(imax[k])[k], imax[k]);
    const Draws d = FitDraws(m, 1, 10, [&](const Calibration&, unsigned seed, double rms) {
      EXPECT_LT(rms, 0.005) << m.name << " seed " << seed;
    });
    std::printf("%-13s mean %.3f %% worst %.3f %%  [%s]\n", m.name.c_str(), 100 * d.mean, 100 * d.worst,
                d.families.c_str());
    if (m.name == "syrm") {
      // The analytic family alone (the path that crashed): a finite fit
      // with a finite covariance.
      FitOptions analytic;
      analytic.model = "analytic";
      auto cal = Fit(EolDraw(m, 1), analytic);
      ASSERT_TRUE(cal.ok()) << cal.status();
      for (double c : cal->covariance()) EXPECT_TRUE(std::isfinite(c));
      EXPECT_TRUE(std::isfinite(cal->Flux(-100, 100).psi_q_wb));
    }
  }
}

// The map not symmetric in iq (psi_q(id, 0) up to ~5 % of scale) on a
// bench that measured one half: nothing in the data can show the asymmetry,
// so the fit uses the machine's symmetry and says so (the other half "by
// symmetry"), and on the measured half it is off by what the symmetric
// model cannot represent (~4 % RMS, docs/fitting.md). Measured on both
// halves the asymmetric model is a candidate, wins, and is within 0.5 %
// over both (FluxErrorOnEveryDraw has five such draws).
TEST(RealMaps, AsymmetricMachineOnOneHalf) {
  const auto t = sim::RealLikeMotors(300)[2];
  ASSERT_NE(t.psi_q_offset_wb, 0.0);
  const MachineMap one = TraitMachine(t, 300), both = BothHalves(one);
  auto a = Fit(EolDraw(one, 1), {});
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_TRUE(a->family().SymmetricInIq()) << a->family().Name();
  EXPECT_EQ(a->iq_halves(), IqHalves::kPositive);
  EXPECT_EQ(a->RegionOf(-150, -150), Region::kBySymmetry);
  auto b = Fit(EolDraw(both, 1), {});
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(b->family().Name(), "smooth-asym");
  EXPECT_EQ(b->iq_halves(), IqHalves::kBoth);
  EXPECT_EQ(b->RegionOf(-150, -150), Region::kMeasured);
  const double e_one = FluxRms(*a, one), e_both = FluxRms(*b, both);
  std::printf("psi-q-offset: one half %s %.3f %% (measured half), both halves %s %.3f %%\n",
              a->family().Name().c_str(), 100 * e_one, b->family().Name().c_str(), 100 * e_both);
  EXPECT_LT(e_both, 0.005);
}

}  // namespace
}  // namespace fluxcal::fit
