// The twin's files: truth (fluxcal.truth.v1), motor.json and plan.json
// (docs/simulation.md).
#include <fstream>
#include <map>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "nlohmann/json.hpp"
#include "simulation/twin.h"

namespace fluxcal::sim {

std::string TruthJson(const TwinConfig& cfg, const SimulationResult& r) {
  using nlohmann::json;
  json j;
  j["format"] = "fluxcal.truth.v1";
  j["serial"] = cfg.serial;
  j["seed"] = cfg.seed;
  json eff = json::array();
  const Effects& e = cfg.effects;
  for (const auto& name : ActiveEffectNames(e)) {
    json p = json::object();
    for (const auto& [k, v] : EffectParameters(e, name)) p[k] = v;
    if (name == "spatial_harmonics") p["order"] = e.order;   // an integer in the file
    eff.push_back({{"effect", name}, {"parameters", p}});
  }
  // Physics outside the catalogue: concealed too, but never to be named;
  // the verdict it calls for is `unexplained` or `partly_explained`.
  json outside = json::array();
  for (const auto& b : e.unmodelled) {
    json p = json::object();
    for (const auto& par : b->Parameters()) p[std::string(par.name)] = par.value;
    outside.push_back({{"effect", std::string(b->Name())}, {"parameters", p}, {"in_catalogue", false}});
  }
  j["concealed_effects"] = eff;
  if (!outside.empty()) j["concealed_outside_catalogue"] = outside;
  j["expected_verdict"] = !outside.empty() ? (eff.empty() ? "unexplained" : "partly_explained")
                                            : (eff.empty() ? "no_mismatch" : "explained");
  j["motor"] = {{"pole_pairs", cfg.motor.pole_pairs}, {"rs_ohm", e.rs_ohm.value_or(cfg.motor.rs_ohm)},
                {"psi_pm_wb", e.psi_pm_wb.value_or(cfg.motor.sat.psi_pm_wb)},
                {"ld0_h", cfg.motor.sat.ld0_h}, {"lq0_h", cfg.motor.sat.lq0_h},
                {"id_sat_a", cfg.motor.sat.id_sat_a}, {"iq_sat_a", cfg.motor.sat.iq_sat_a},
                {"g_cross_h", e.cross_saturation != 0 ? e.cross_saturation : cfg.motor.sat.g_cross_h},
                {"ix_a", cfg.motor.sat.ix_a}};
  auto pt = [](const TruthPoint& t) {
    json o = {{"id_true_a", t.id_true_a}, {"iq_true_a", t.iq_true_a}, {"speed_rpm", t.speed_rpm},
              {"psi_d_wb", t.psi_d_wb}, {"psi_q_wb", t.psi_q_wb}, {"ldd_h", t.ldd_h},
              {"lqq_h", t.lqq_h}, {"ldq_h", t.ldq_h}, {"ld_app_h", t.ld_app_h},
              {"lq_app_h", t.lq_app_h}, {"torque_nm", t.torque_nm}, {"psi_pm_wb", t.psi_pm_wb},
              {"temperature_c", t.temperature_c}};
    if (!t.id.empty()) o["id"] = t.id;
    return o;
  };
  j["points"] = json::array();
  for (const auto& t : r.truth_points) j["points"].push_back(pt(t));
  j["steady_state"] = json::array();
  for (const auto& t : r.truth_steady_state) j["steady_state"].push_back(pt(t));
  return j.dump(2) + "\n";
}

namespace {

absl::StatusOr<nlohmann::json> ReadJsonFile(const std::string& path) {
  std::ifstream f(path);
  if (!f) return absl::NotFoundError(absl::StrCat(path, ": file not found"));
  std::stringstream ss;
  ss << f.rdbuf();
  try {
    return nlohmann::json::parse(ss.str());
  } catch (const nlohmann::json::parse_error& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": field '(json)': ", e.what()));
  }
}

// Reads known numeric keys of an object; unknown keys are errors.
absl::Status ReadNumbers(const std::string& path, const std::string& prefix, const nlohmann::json& o,
                         const std::map<std::string, double*>& fields) {
  if (!o.is_object()) return absl::InvalidArgumentError(absl::StrCat(path, ": field '", prefix, "': expected an object"));
  for (const auto& [k, v] : o.items()) {
    auto it = fields.find(k);
    if (it == fields.end()) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", prefix, k, "': unknown key"));
    }
    if (!v.is_number()) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", prefix, k, "': expected a number"));
    }
    *it->second = v.get<double>();
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status LoadMotorJson(const std::string& path, TwinConfig* cfg) {
  auto j = ReadJsonFile(path);
  if (!j.ok()) return j.status();
  if (!j->is_object()) return absl::InvalidArgumentError(absl::StrCat(path, ": expected an object"));
  double pp = cfg->motor.pole_pairs;
  for (const auto& [k, v] : j->items()) {
    absl::Status st;
    if (k == "serial") {
      if (!v.is_string()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'serial': expected a string"));
      cfg->serial = v.get<std::string>();
    } else if (k == "motor") {
      st = ReadNumbers(path, "motor.", v,
                       {{"pole_pairs", &pp}, {"rs_ohm", &cfg->motor.rs_ohm},
                        {"psi_pm_wb", &cfg->motor.sat.psi_pm_wb}, {"ld0_h", &cfg->motor.sat.ld0_h},
                        {"lq0_h", &cfg->motor.sat.lq0_h}, {"id_sat_a", &cfg->motor.sat.id_sat_a},
                        {"iq_sat_a", &cfg->motor.sat.iq_sat_a}, {"g_cross_h", &cfg->motor.sat.g_cross_h},
                        {"ix_a", &cfg->motor.sat.ix_a},
                        {"psi_pm_temp_coeff_per_k", &cfg->motor.psi_pm_temp_coeff_per_k}});
    } else if (k == "drive") {
      st = ReadNumbers(path, "drive.", v,
                       {{"udc_v", &cfg->drive.udc_v}, {"f_pwm_hz", &cfg->drive.f_pwm_hz},
                        {"nominal_dead_time_s", &cfg->drive.nominal_dead_time_s}});
    } else if (k == "sensors") {
      double counts = cfg->sensors.encoder_counts_per_mech_rev;
      st = ReadNumbers(path, "sensors.", v,
                       {{"noise_a", &cfg->sensors.noise_a}, {"adc_lsb_a", &cfg->sensors.adc_lsb_a},
                        {"encoder_counts_per_mech_rev", &counts}, {"udc_noise_v", &cfg->sensors.udc_noise_v}});
      cfg->sensors.encoder_counts_per_mech_rev = static_cast<int>(counts);
    } else if (k == "control") {
      nlohmann::json numbers = v;
      if (v.is_object() && v.contains("gain_scheduled")) {
        if (!v["gain_scheduled"].is_boolean()) {
          return absl::InvalidArgumentError(
              absl::StrCat(path, ": field 'control.gain_scheduled': expected true or false"));
        }
        cfg->control.gain_scheduled = v["gain_scheduled"].get<bool>();
        numbers.erase("gain_scheduled");
      }
      st = ReadNumbers(path, "control.", numbers,
                       {{"bandwidth_hz", &cfg->control.bandwidth_hz},
                        {"integral_corner_hz", &cfg->control.integral_corner_hz},
                        {"ld_nominal_h", &cfg->control.ld_nominal_h},
                        {"lq_nominal_h", &cfg->control.lq_nominal_h}});
    } else if (k == "injection") {
      st = ReadNumbers(path, "injection.", v,
                       {{"amplitude_v", &cfg->injection.amplitude_v},
                        {"frequency_hz", &cfg->injection.frequency_hz}});
    } else {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", k, "': unknown key"));
    }
    if (!st.ok()) return st;
  }
  if (pp < 1 || pp != std::floor(pp)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": field 'motor.pole_pairs': must be a positive integer"));
  }
  cfg->motor.pole_pairs = static_cast<int>(pp);
  return absl::OkStatus();
}

absl::StatusOr<Plan> LoadPlanJson(const std::string& path) {
  auto j = ReadJsonFile(path);
  if (!j.ok()) return j.status();
  Plan plan;
  plan.points.clear();
  if (!j->is_object()) return absl::InvalidArgumentError(absl::StrCat(path, ": expected an object"));
  for (const auto& [k, v] : j->items()) {
    if (k == "settle_s" || k == "record_s") {
      if (!v.is_number()) return absl::InvalidArgumentError(absl::StrCat(path, ": field '", k, "': expected a number"));
      (k == "settle_s" ? plan.settle_s : plan.record_s) = v.get<double>();
    } else if (k == "points") {
      if (!v.is_array()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'points': expected an array"));
      for (size_t n = 0; n < v.size(); ++n) {
        PlanPoint p;
        p.id = absl::StrFormat("p%03d", n);
        const auto& o = v[n];
        if (o.contains("id")) {
          if (!o["id"].is_string()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'points[", n, "].id': expected a string"));
          p.id = o["id"].get<std::string>();
        }
        nlohmann::json rest = o;
        rest.erase("id");
        if (o.contains("sector")) {
          if (!o["sector"].is_number_integer() || o["sector"].get<long>() < 0 || o["sector"].get<long>() > 1000) {
            return absl::InvalidArgumentError(
                absl::StrCat(path, ": field 'points[", n, "].sector': expected an integer 0..1000"));
          }
          p.sector = o["sector"].get<int>();
          rest.erase("sector");
        }
        auto st = ReadNumbers(path, absl::StrCat("points[", n, "]."), rest,
                              {{"id_ref_a", &p.id_ref_a}, {"iq_ref_a", &p.iq_ref_a},
                               {"speed_rpm", &p.speed_rpm}, {"theta_e_rad", &p.theta_e_rad},
                               {"temperature_c", &p.temperature_c}, {"udc_v", &p.udc_v}});
        if (!st.ok()) return st;
        if (p.udc_v < 0) {
          return absl::InvalidArgumentError(absl::StrCat(path, ": field 'points[", n, "].udc_v': must be positive (0 or absent: the drive's)"));
        }
        plan.points.push_back(p);
      }
    } else if (k == "steady_state") {
      if (!v.is_array()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'steady_state': expected an array"));
      for (size_t n = 0; n < v.size(); ++n) {
        PlanSteadyState s;
        auto st = ReadNumbers(path, absl::StrCat("steady_state[", n, "]."), v[n],
                              {{"id_ref_a", &s.id_ref_a}, {"iq_ref_a", &s.iq_ref_a},
                               {"speed_rpm", &s.speed_rpm}, {"temperature_c", &s.temperature_c}});
        if (!st.ok()) return st;
        plan.steady_state.push_back(s);
      }
    } else {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", k, "': unknown key"));
    }
  }
  return plan;
}

}  // namespace fluxcal::sim
