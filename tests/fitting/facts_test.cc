// What a calibration says about the machine and drive: pole pairs always
// (a fit refuses without them), Rs, the nominal psi_pm and Udc as the data
// stated them, absent otherwise; JSON round trip, and files written before
// the facts were optional still load with Rs and Udc unknown.
#include <cmath>

#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "simulation/twin.h"

namespace fluxcal::fit {
namespace {

// Inductance points of the twin motor on a grid, without any fact.
FitData Points() {
  const sim::AnalyticMotor m{sim::MotorParams{}};
  FitData d;
  for (int a = 0; a < 5; ++a) {
    for (int b = 0; b < 5; ++b) {
      InductanceObservation o;
      o.id_a = -100 + 25 * a;
      o.iq_a = 25 * b;
      const auto L = m.Inductance(o.id_a, o.iq_a);
      o.ldd_h = L.ldd_h;
      o.lqq_h = L.lqq_h;
      o.ldq_h = L.ldq_h;
      o.ldd_h_std = o.lqq_h_std = o.ldq_h_std = 1e-7;
      d.inductances.push_back(o);
    }
  }
  return d;
}

TEST(Facts, FitRefusesUnknownPolePairs) {
  FitData d = Points();
  d.serial = "IPM-PP";
  FitOptions o;
  o.model = "analytic";
  auto cal = Fit(d, o);
  ASSERT_EQ(cal.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(cal.status().message().find("pole_pairs: unknown"), std::string::npos) << cal.status();
  EXPECT_NE(cal.status().message().find("--pole-pairs"), std::string::npos) << cal.status();
}

TEST(Facts, StatedFactsTravelInTheCalibration) {
  FitData d = Points();
  d.serial = "IPM-FACTS";
  d.pole_pairs = 4;
  d.psi_pm_prior_wb = 0.0114;
  FitOptions o;
  o.model = "analytic";
  auto bare = Fit(d, o);
  ASSERT_TRUE(bare.ok()) << bare.status();
  EXPECT_FALSE(bare->rs_ohm().has_value());
  EXPECT_FALSE(bare->udc_v().has_value());
  EXPECT_EQ(*bare->psi_pm_nominal_wb(), 0.0114);
  nlohmann::json j = bare->ToJson();
  EXPECT_FALSE(j.contains("rs_ohm")) << "an unknown Rs is not written as 0";
  EXPECT_FALSE(j.contains("udc_v"));
  d.rs_ohm = 0.011;
  d.udc_v = 48.0;
  auto full = Fit(d, o);
  ASSERT_TRUE(full.ok());
  j = full->ToJson();
  EXPECT_EQ(j["rs_ohm"].get<double>(), 0.011);
  EXPECT_EQ(j["udc_v"].get<double>(), 48.0);
  EXPECT_EQ(j["psi_pm_nominal_wb"].get<double>(), 0.0114);
  auto back = Calibration::FromJson(j);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back->rs_ohm(), 0.011);
  EXPECT_EQ(*back->udc_v(), 48.0);
  EXPECT_EQ(*back->psi_pm_nominal_wb(), 0.0114);
  EXPECT_EQ(back->pole_pairs(), 4);
  EXPECT_EQ(back->ToJson().dump(), j.dump());

  // A file of before: rs_ohm 0 for an Rs nobody stated, no nominal psi_pm,
  // no Udc. It loads, with those unknown.
  j["rs_ohm"] = 0.0;
  j.erase("udc_v");
  j.erase("psi_pm_nominal_wb");
  auto old = Calibration::FromJson(j);
  ASSERT_TRUE(old.ok()) << old.status();
  EXPECT_FALSE(old->rs_ohm().has_value());
  EXPECT_FALSE(old->udc_v().has_value());
  EXPECT_FALSE(old->psi_pm_nominal_wb().has_value());
  // Out of range: named.
  j["pole_pairs"] = 0;
  EXPECT_NE(Calibration::FromJson(j).status().message().find("field 'pole_pairs'"), std::string::npos);
  j["pole_pairs"] = 4;
  j["udc_v"] = -5.0;
  EXPECT_NE(Calibration::FromJson(j).status().message().find("field 'udc_v'"), std::string::npos);
}

TEST(Facts, ManifestStatesThem) {
  io::Manifest m;
  m.serial = "IPM-M";
  m.motor.pole_pairs = 3;
  m.motor.psi_pm_wb = 0.02;
  m.drive.udc_v = 300.0;
  m.drive.f_sample_hz = 10000;
  const FitData d = FitDataFromHfRows(&m, {});
  EXPECT_EQ(d.serial, "IPM-M");
  EXPECT_EQ(d.pole_pairs, 3);
  EXPECT_EQ(*d.psi_pm_prior_wb, 0.02);
  EXPECT_EQ(*d.udc_v, 300.0);
  EXPECT_FALSE(d.rs_ohm.has_value()) << "the manifest states no Rs";
  const FitData none = FitDataFromHfRows(nullptr, {});
  EXPECT_EQ(none.pole_pairs, 0);
  EXPECT_TRUE(none.serial.empty());
  EXPECT_FALSE(none.psi_pm_prior_wb || none.rs_ohm || none.udc_v);
}

// A machine without magnets (psi_pm stated 0): fluxcal's d is its
// low-permeance axis (docs/recording-format.md, "Machines without
// magnets"). The same saturating reluctance machine in that frame fits; in
// the reluctance-machine frame (d on the high-permeance axis, id = iq',
// iq = -id' ... rotated by 90 degrees) it is refused, whether the data are
// identified inductances or flux nodes, naming the field and the rotation.
TEST(Facts, MachineWithoutMagnetsTellsItsAxes) {
  // psi_d = Ld id / (1 + |id| / 60), psi_q = Lq iq / (1 + |iq| / 40): a
  // conservative map (diagonal Jacobian), Lq 5x Ld.
  const double ld = 0.4e-3, lq = 2.0e-3;
  auto flux = [&](double id, double iq, double* pd, double* pq) {
    *pd = ld * id / (1 + std::abs(id) / 60);
    *pq = lq * iq / (1 + std::abs(iq) / 40);
  };
  auto inductance = [&](double id, double iq, double* ldd, double* lqq) {
    *ldd = ld / std::pow(1 + std::abs(id) / 60, 2);
    *lqq = lq / std::pow(1 + std::abs(iq) / 40, 2);
  };
  for (bool rotated : {false, true}) {
    FitData hf, map;
    hf.pole_pairs = map.pole_pairs = 2;
    hf.psi_pm_prior_wb = map.psi_pm_prior_wb = 0.0;
    for (int a = 0; a <= 5; ++a) {
      for (int b = 0; b <= 5; ++b) {
        // fluxcal's frame: id in [-100, 0], iq in [0, 100]; rotated: the
        // high-permeance axis called d (id' = iq, iq' = -id).
        const double id = -100 + 20 * a, iq = 20 * b;
        double pd, pq, ldd, lqq;
        flux(id, iq, &pd, &pq);
        inductance(id, iq, &ldd, &lqq);
        InductanceObservation o;
        o.id_a = rotated ? iq : id;
        o.iq_a = rotated ? -id : iq;
        o.ldd_h = rotated ? lqq : ldd;
        o.lqq_h = rotated ? ldd : lqq;
        o.ldq_h = 0.0;
        o.ldd_h_std = 1e-3 * o.ldd_h;
        o.lqq_h_std = 1e-3 * o.lqq_h;
        o.ldq_h_std = 1e-3 * o.ldd_h;
        hf.inductances.push_back(o);
        FluxObservation f;
        f.id_a = o.id_a;
        f.iq_a = o.iq_a;
        f.psi_d_wb = rotated ? pq : pd;
        f.psi_q_wb = rotated ? -pd : pq;
        f.psi_std_wb = 1e-5;
        map.fluxes.push_back(f);
      }
    }
    for (const FitData* d : {&hf, &map}) {
      auto cal = Fit(*d, {});
      if (!rotated) {
        EXPECT_TRUE(cal.ok()) << cal.status();
        continue;
      }
      ASSERT_FALSE(cal.ok());
      EXPECT_EQ(cal.status().code(), absl::StatusCode::kInvalidArgument);
      const std::string m(cal.status().message());
      EXPECT_NE(m.find("motor.psi_pm_wb"), std::string::npos) << m;
      EXPECT_NE(m.find(d == &hf ? "identified points" : "flux nodes"), std::string::npos) << m;
      EXPECT_NE(m.find("id = -iq'"), std::string::npos) << m;
    }
  }
}

}  // namespace
}  // namespace fluxcal::fit
