#include "cli/support_flux_map.h"

#include <string>

namespace fluxcal::cli {

FlagSpecs FluxMapConventionFlags() {
  return {
      {"convention", "C",
       "axes of the map: auto|fluxcal|motulator|syre (default auto: detected from the node at zero current)"},
      {"current", "S", "current scaling of the map: peak|rms|power-invariant (default peak, amplitude-invariant)"},
      {"flux-amplitude", "S", "flux scaling of the map: peak|rms|power-invariant (default peak)"},
      {"units", "U", "flux unit of the map: Wb|Vs|mWb|mVs (default the psi columns' suffix, else Wb)"},
  };
}

bool HasFluxMapConventionFlag(const ParsedArgs& args) {
  for (const auto& f : FluxMapConventionFlags()) {
    if (args.Has(f.name)) return true;
  }
  return false;
}

absl::StatusOr<io::FluxMapConvention> FluxMapConventionFromArgs(const ParsedArgs& args) {
  io::FluxMapConvention c;
  auto bad = [](const char* flag, const char* expected, const std::string& got) {
    return absl::InvalidArgumentError(std::string("flag --") + flag + ": expected " + expected + ", got '" + got + "'");
  };
  if (auto v = args.Get("convention")) {
    auto a = io::FluxMapAxesFromName(*v);
    if (!a) return bad("convention", "auto, fluxcal, motulator or syre", *v);
    c.axes = *a;
  }
  for (const char* flag : {"current", "flux-amplitude"}) {
    if (auto v = args.Get(flag)) {
      auto s = io::AmplitudeScalingFromName(*v);
      if (!s) return bad(flag, "peak, rms or power-invariant", *v);
      (std::string(flag) == "current" ? c.current : c.flux) = *s;
    }
  }
  if (auto v = args.Get("units")) {
    auto u = io::FluxUnitFromName(*v);
    if (!u || *u == io::FluxUnit::kFromHeader) return bad("units", "Wb, Vs, mWb or mVs", *v);
    c.flux_unit = *u;
  }
  return c;
}

nlohmann::json FluxMapConventionJson(const io::AppliedFluxMapConvention& c) {
  return {{"axes", io::Name(c.axes)},
          {"axes_source", c.axes_detected ? "detected" : "flag"},
          {"current", io::Name(c.current)},
          {"flux_amplitude", io::Name(c.flux)},
          {"flux_unit", io::Name(c.flux_unit)},
          {"flux_unit_source", c.flux_unit_source},
          {"current_factor", c.current_factor},
          {"flux_factor", c.flux_factor},
          {"detail", c.detail},
          {"description", c.Describe()}};
}

}  // namespace fluxcal::cli
