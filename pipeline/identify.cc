#include "pipeline/identify.h"

#include "fitting/fit.h"

namespace fluxcal::pipeline {

absl::StatusOr<ident::Method> ParseIdentifyMethod(const std::string& name) { return ident::ParseMethod(name); }

const char* IdentifyMethodName(ident::Method method) { return ident::MethodName(method); }

absl::StatusOr<std::vector<ident::HfPointResult>> IdentifyEveryPoint(const io::RecordingSet& set,
                                                                     const ident::IdentifyOptions& options) {
  return ident::IdentifySet(set, options);
}

std::optional<double> InjectionFluxRadiusWb(const io::Manifest& manifest, const ident::HfPointResult& result) {
  return fit::HfFluxRadiusOf(manifest, result);
}

}  // namespace fluxcal::pipeline
