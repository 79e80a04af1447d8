// Facts about the machine and drive a fit rests on: serial, pole pairs,
// the nominal magnet flux psi_pm, Rs and the DC-link voltage Udc. They come
// from the recording set's manifest, a flux map's node at zero current, or
// the command line; one that nobody states stays unknown, and where a
// calibration cannot do without it the fit is refused with the flag to
// give (docs/cli.md, "Machine facts"). The one rule, for every way
// `fluxcal fit` reads its data.
#ifndef FLUXCAL_PIPELINE_FACTS_H_
#define FLUXCAL_PIPELINE_FACTS_H_

#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "fitting/fit.h"

namespace fluxcal::pipeline {

// What the command line states (--serial, --pole-pairs, --psi-pm-wb,
// --rs-ohm, --udc-v); unset: not stated.
struct StatedFacts {
  std::optional<std::string> serial;
  std::optional<int> pole_pairs;
  std::optional<double> psi_pm_wb, rs_ohm, udc_v;
  // Magnet temperature (--magnet-temp-coeff-per-k, --magnet-reference-c):
  // the relative change of psi_pm per kelvin, and the magnet temperature
  // the data were taken at, degC (for data that record none, e.g. a flux
  // map: every observation is taken as at that temperature).
  std::optional<double> psi_pm_temp_coeff_per_k, magnet_reference_c;
};

// Where the fit data came from, i.e. what it states by itself.
enum class FactSource {
  kRecordingSet,   // a set: its manifest states serial, pole pairs and (optionally) psi_pm, Rs, Udc
  kHfResults,      // a bare hf_results.csv: states nothing about the machine
  kFluxMap,        // a flux map: psi_pm at its zero-current node, nothing else
};

// Merges `stated` into `data`'s facts. A stated fact the source lacks fills
// the gap; one the source states differently is refused (InvalidArgument
// naming the flag and the source's value: a set is the bench's record, and
// a silent override would hide which of the two was wrong); an equal one
// is accepted. Then refused, naming every missing flag at once:
//   - serial and pole pairs unknown;
//   - psi_pm unknown while the data cannot observe it: differential
//     inductances alone do not (d psi / d i says nothing of psi at zero
//     current); steady-state rows at speed or flux-map nodes do.
// Rs and Udc stay unknown when nobody states them (the calibration records
// them absent; exports that need them ask); so do the magnet temperature
// coefficient and reference. --magnet-reference-c is refused when the data
// record a temperature_c of their own (the reference is then their mean,
// docs/fitting.md). Values are range-checked (pole pairs 1..100, psi_pm >=
// 0, Rs >= 0, Udc > 0, the coefficient in io::kMinPsiPmTempCoeffPerK ..
// kMaxPsiPmTempCoeffPerK, the reference -60 .. 250 degC, serial as the set
// format's rule). `notes` (optional) receives one line per fact a flag
// supplied.
absl::Status ApplyStatedFacts(const StatedFacts& stated, FactSource source, fit::FitData* data,
                              std::vector<std::string>* notes = nullptr);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_FACTS_H_
