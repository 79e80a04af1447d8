// fluxcal identify <recording-set> [--method paper|lsq] [--json|--csv]
// One row per operating point: differential inductances with standard
// errors and quality flags (pipeline/identify.h).
#include <cmath>
#include <cstdio>
#include <iostream>

#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_progress.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "pipeline/identify.h"

namespace fluxcal::cli {
namespace {

const FlagSpecs kIdentifyFlags = {
    {"method", "M", "paper|lsq: the paper's estimator or least squares over the record (default lsq)"},
    {"no-compensation", "", "do not compensate the delay and filters of the measurement chain"},
    {"csv", "", "print the points as CSV"},
    kJsonFlag,
};

int RunIdentify(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kIdentifyFlags);
  if (!args.ok() || args->positional.size() != 1) {
    std::fprintf(stderr, "%s\nusage: fluxcal identify <recording-set> [--method paper|lsq] "
                         "[--json|--csv] [--no-compensation]\n",
                 args.ok() ? "expected one recording set" : std::string(args.status().message()).c_str());
    return 2;
  }
  ident::IdentifyOptions opt;
  auto method = pipeline::ParseIdentifyMethod(args->Get("method").value_or("lsq"));
  if (!method.ok()) {
    std::fprintf(stderr, "fluxcal identify: %s\n", std::string(method.status().message()).c_str());
    return 2;
  }
  opt.method = *method;
  opt.compensate_delay_filters = !args->Has("no-compensation");
  auto set = io::ReadRecordingSet(args->positional[0]);
  if (!set.ok()) {
    std::fprintf(stderr, "fluxcal identify: %s\n", std::string(set.status().message()).c_str());
    return 1;
  }
  opt.progress = ProgressLine("identify: point").Callback();
  auto results = pipeline::IdentifyEveryPoint(*set, opt);
  if (!results.ok()) {
    std::fprintf(stderr, "fluxcal identify: %s\n", std::string(results.status().message()).c_str());
    return 1;
  }
  auto num = [](double v, bool present) { return present ? absl::StrFormat("%.9g", v) : std::string(); };
  if (args->Has("json")) {
    nlohmann::json j;
    j["serial"] = set->manifest.serial;
    j["method"] = pipeline::IdentifyMethodName(opt.method);
    j["points"] = nlohmann::json::array();
    for (const auto& r : *results) {
      nlohmann::json p = {{"point", r.point}, {"id_a", r.id_a}, {"iq_a", r.iq_a},
                          {"speed_rpm", r.speed_rpm}, {"ld_h", r.ld_h}, {"lq_h", r.lq_h},
                          {"ld_h_std", r.ld_h_std}, {"lq_h_std", r.lq_h_std},
                          {"periods", r.periods_used}, {"residual_rms_a", r.residual_rms_a},
                          {"snr_db", r.snr_db}, {"harmonic_ratio", r.harmonic_ratio},
                          {"near_zero_fraction", r.near_zero_fraction},
                          {"dead_time_sideband_ratio", std::isfinite(r.dead_time_sideband_ratio)
                                                           ? nlohmann::json(r.dead_time_sideband_ratio)
                                                           : nlohmann::json(nullptr)},
                          {"reliable", r.reliable}, {"flags", r.flags}};
      // The injection's flux radius, Wb (docs/fitting.md, "Large-signal
      // HF"): what a station sends with the point so that a stored fit
      // predicts it as the injection measured it; null without a rotating
      // injection in the manifest.
      const auto radius = pipeline::InjectionFluxRadiusWb(set->manifest, r);
      p["hf_flux_radius_wb"] = radius ? nlohmann::json(*radius) : nlohmann::json(nullptr);
      // The command's negative sequence, V (docs/identification.md, Sec. 8):
      // what the bench's loop put at 2 w_e - w_i, solved for in (E2).
      p["v_neg_v"] = std::isfinite(r.ld_h) ? nlohmann::json(std::abs(r.v_neg_eff_v)) : nlohmann::json(nullptr);
      if (r.has_ldq) {
        p["ldq_h"] = r.ldq_h; p["ldq_h_std"] = r.ldq_h_std;
        p["r_hf_ohm"] = r.r_hf_ohm; p["r_hf_ohm_std"] = r.r_hf_ohm_std;
      } else {
        p["ldq_h"] = nullptr; p["ldq_h_std"] = nullptr;
        p["r_hf_ohm"] = nullptr; p["r_hf_ohm_std"] = nullptr;
      }
      j["points"].push_back(p);
    }
    PrintJson(j);
    return 0;
  }
  // CSV is the default human/machine form (--csv accepted for clarity).
  std::cout << "point,id_a,iq_a,speed_rpm,ld_h,lq_h,ldq_h,r_hf_ohm,ld_h_std,lq_h_std,ldq_h_std,"
               "r_hf_ohm_std,periods,residual_rms_a,snr_db,harmonic_ratio,reliable,flags\n";
  for (const auto& r : *results) {
    std::cout << absl::StrFormat("%s,%.4f,%.4f,%.2f,%s,%s,%s,%s,%s,%s,%s,%s,%g,%.4g,%.1f,%.3g,%d,%s\n",
                                 r.point, r.id_a, r.iq_a, r.speed_rpm, num(r.ld_h, true),
                                 num(r.lq_h, true), num(r.ldq_h, r.has_ldq), num(r.r_hf_ohm, r.has_ldq),
                                 num(r.ld_h_std, true), num(r.lq_h_std, true),
                                 num(r.ldq_h_std, r.has_ldq), num(r.r_hf_ohm_std, r.has_ldq),
                                 r.periods_used, r.residual_rms_a, r.snr_db, r.harmonic_ratio,
                                 r.reliable ? 1 : 0, absl::StrJoin(r.flags, ";"));
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("identify", "identify differential inductances per point (HF injection)",
                         RunIdentify,
                         "fluxcal identify <recording-set> [--method paper|lsq] [--json|--csv] [--no-compensation]",
                         kIdentifyFlags);

}  // namespace fluxcal::cli
