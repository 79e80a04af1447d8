// The limits the table tests compute for: the twin motor's pole pairs and
// Rs, the twin drive's Udc (the test motors are the twin's analytic family)
// and a current limit of 150 A. Stated here, once: tables::MachineLimits has
// no defaults of any machine.
#ifndef FLUXCAL_TESTS_TABLES_TWIN_LIMITS_H_
#define FLUXCAL_TESTS_TABLES_TWIN_LIMITS_H_

#include "simulation/twin.h"
#include "tables/tables.h"

namespace fluxcal::tables {

inline MachineLimits TwinLimits(double i_max_a = 150.0) {
  MachineLimits lim;
  lim.pole_pairs = sim::MotorParams().pole_pairs;
  lim.rs_ohm = sim::MotorParams().rs_ohm;
  lim.udc_v = sim::DriveParams().udc_v;
  lim.i_max_a = i_max_a;
  return lim;
}

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TESTS_TABLES_TWIN_LIMITS_H_
