// fluxcal query calibration.json --id-a -20 --iq-a 40 [--json]
// fluxcal query calibration.json --grid ID_MIN:ID_MAX:N,IQ_MIN:IQ_MAX:M  (CSV)
// Flux linkage, differential and apparent inductance and torque with
// standard deviations at any (id, iq), where the point lies (measured, by
// symmetry, extrapolated) and whether the model is valid there (its
// differential inductance positive definite).
#include <cstdio>
#include <iostream>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_remote.h"
#include "nlohmann/json.hpp"
#include "pipeline/pipeline.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("query", m, code); }

nlohmann::json ToJson(double id, double iq, const fit::FluxPrediction& p) {
  return {{"id_a", id}, {"iq_a", iq}, {"psi_d_wb", p.psi_d_wb}, {"psi_q_wb", p.psi_q_wb},
          {"ldd_h", p.ldd_h}, {"lqq_h", p.lqq_h}, {"ldq_h", p.ldq_h}, {"ld_app_h", p.ld_app_h},
          {"lq_app_h", p.lq_app_h}, {"torque_nm", p.torque_nm}, {"psi_d_wb_std", p.psi_d_wb_std},
          {"psi_q_wb_std", p.psi_q_wb_std}, {"ldd_h_std", p.ldd_h_std}, {"lqq_h_std", p.lqq_h_std},
          {"ldq_h_std", p.ldq_h_std}, {"ld_app_h_std", p.ld_app_h_std}, {"lq_app_h_std", p.lq_app_h_std},
          {"torque_nm_std", p.torque_nm_std}, {"extrapolated", p.extrapolated},
          {"region", pipeline::FluxRegionName(p.region)}, {"valid", p.valid}, {"invalid_reason", p.invalid_reason}};
}

const char* kCsvHeader =
    "id_a,iq_a,psi_d_wb,psi_q_wb,ldd_h,lqq_h,ldq_h,ld_app_h,lq_app_h,torque_nm,psi_d_wb_std,"
    "psi_q_wb_std,ldd_h_std,lqq_h_std,ldq_h_std,torque_nm_std,extrapolated,region,valid\n";

std::string CsvRow(double id, double iq, const fit::FluxPrediction& p) {
  return absl::StrFormat("%g,%g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.3g,%.3g,%.3g,%.3g,%.3g,%.3g,%d,%s,%d\n",
                         id, iq, p.psi_d_wb, p.psi_q_wb, p.ldd_h, p.lqq_h, p.ldq_h, p.ld_app_h,
                         p.lq_app_h, p.torque_nm, p.psi_d_wb_std, p.psi_q_wb_std, p.ldd_h_std,
                         p.lqq_h_std, p.ldq_h_std, p.torque_nm_std, p.extrapolated ? 1 : 0,
                         pipeline::FluxRegionName(p.region), p.valid ? 1 : 0);
}

// The text form's note on where the point lies (fit::Region).
const char* RegionNote(fit::Region r) {
  switch (r) {
    case fit::Region::kMeasured: return "";
    case fit::Region::kBySymmetry: return " (by symmetry: the measured half mirrored, psi_d even, psi_q odd in iq)";
    case fit::Region::kExtrapolated: return " (extrapolated)";
  }
  return "";
}

bool ParseAxis(const std::string& s, double* lo, double* hi, int* n) {
  std::vector<std::string> f = absl::StrSplit(s, ':');
  return f.size() == 3 && absl::SimpleAtod(f[0], lo) && absl::SimpleAtod(f[1], hi) &&
         absl::SimpleAtoi(f[2], n) && *n >= 1 && *n <= 10000;
}

}  // namespace

namespace {
// Local (calibration file) and remote (--server, serial) query; --grid and
// --csv are local only, --server and --version remote only.
const FlagSpecs kQueryFlags = {
    {"id-a", "A", "d-axis current, A (negative: field weakening)"},
    {"iq-a", "A", "q-axis current, A"},
    {"grid", "IDMIN:IDMAX:N,IQMIN:IQMAX:M", "local only: a grid of points instead of one (CSV on stdout), A"},
    {"csv", "", "local only: one point as a CSV row with header"},
    ServerFlag("ask the service about a serial's stored calibration"),
    kServerVersionFlag,
    kJsonFlag,
};
}  // namespace

int RunQueryLocal(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, WithoutFlags(kQueryFlags, {"server", "version"}));
  if (!args.ok()) return Fail(std::string(args.status().message()), 2);
  if (args->positional.size() != 1) {
    return Fail("usage: fluxcal query calibration.json (--id-a A --iq-a A | --grid "
                "IDMIN:IDMAX:N,IQMIN:IQMAX:M) [--json|--csv]", 2);
  }
  auto cal = pipeline::LoadCalibrationFile(args->positional[0]);
  if (!cal.ok()) return Fail(std::string(cal.status().message()));
  if (auto g = args->Get("grid")) {
    std::vector<std::string> axes = absl::StrSplit(*g, ',');
    double a0, a1, b0, b1;
    int na, nb;
    if (axes.size() != 2 || !ParseAxis(axes[0], &a0, &a1, &na) || !ParseAxis(axes[1], &b0, &b1, &nb)) {
      return Fail("flag --grid: expected IDMIN:IDMAX:N,IQMIN:IQMAX:M", 2);
    }
    nlohmann::json arr = nlohmann::json::array();
    std::string csv = kCsvHeader;
    for (int i = 0; i < na; ++i) {
      for (int j = 0; j < nb; ++j) {
        const double id = na == 1 ? a0 : a0 + (a1 - a0) * i / (na - 1);
        const double iq = nb == 1 ? b0 : b0 + (b1 - b0) * j / (nb - 1);
        const auto p = cal->Predict(id, iq);
        if (args->Has("json")) arr.push_back(ToJson(id, iq, p)); else csv += CsvRow(id, iq, p);
      }
    }
    if (args->Has("json")) PrintJson({{"serial", cal->serial()}, {"points", arr}});
    else std::cout << csv;
    return 0;
  }
  auto id = args->GetDouble("id-a");
  auto iq = args->GetDouble("iq-a");
  if (!id.ok() || !iq.ok() || !id->has_value() || !iq->has_value()) {
    return Fail("need --id-a and --iq-a (finite numbers) or --grid", 2);
  }
  const auto p = cal->Predict(**id, **iq);
  if (args->Has("json")) {
    PrintJson(ToJson(**id, **iq, p));
  } else if (args->Has("csv")) {
    std::cout << kCsvHeader << CsvRow(**id, **iq, p);
  } else {
    std::printf("serial %s at id = %g A, iq = %g A%s\n", cal->serial().c_str(), **id, **iq, RegionNote(p.region));
    if (!p.valid) std::printf("  NOT VALID: %s (differential inductance not positive definite)\n", p.invalid_reason.c_str());
    std::printf("  psi_d = %.6g +- %.2g Wb   psi_q = %.6g +- %.2g Wb\n", p.psi_d_wb, p.psi_d_wb_std,
                p.psi_q_wb, p.psi_q_wb_std);
    std::printf("  Ldd = %.5g mH  Lqq = %.5g mH  Ldq = %.4g mH (differential)\n", p.ldd_h * 1e3,
                p.lqq_h * 1e3, p.ldq_h * 1e3);
    std::printf("  Ld_app = %.5g mH  Lq_app = %.5g mH (apparent)   torque = %.4g +- %.2g N m\n",
                p.ld_app_h * 1e3, p.lq_app_h * 1e3, p.torque_nm, p.torque_nm_std);
  }
  return 0;
}

namespace {
int RunQuery(const std::vector<std::string>& argv) {
  // With --server the positional argument is a serial and the service
  // answers from its stored calibration; otherwise a calibration file.
  for (const auto& a : argv) {
    if (a == "--server" || a.rfind("--server=", 0) == 0) {
      return RunRemoteQuery(argv, WithoutFlags(kQueryFlags, {"grid", "csv"}));
    }
  }
  return RunQueryLocal(argv);
}
}  // namespace

FLUXCAL_REGISTER_COMMAND("query", "flux linkage and inductance of a calibration at any (id, iq)", RunQuery,
                         "fluxcal query calibration.json (--id-a A --iq-a A | --grid IDMIN:IDMAX:N,IQMIN:IQMAX:M) [--json|--csv]\n" +
                             std::string(kRemoteQueryUsage),
                         kQueryFlags);

}  // namespace fluxcal::cli
