// The fit as engineers check it: identified inductances with their error
// bars against the fitted surfaces, as SVG drawn with plot/.
#ifndef FLUXCAL_FITTING_PLOT_H_
#define FLUXCAL_FITTING_PLOT_H_

#include <string>

#include "fitting/calibration.h"
#include "fitting/fit.h"

namespace fluxcal::fit {

// Two panels: Ldd against id, one curve per distinct iq of the data; Lqq
// against iq, one curve per distinct id; inductances in mH on round ticks.
// Identified points as dots (class "point") with +-1 sigma bars in the
// colour of their curve; the fitted surface as lines (class "line"), with
// stretches outside the measured region dashed; curves that lie on top of
// each other drawn once, their levels named together in one legend entry.
std::string PlotFitSvg(const Calibration& cal, const FitData& data);

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_PLOT_H_
