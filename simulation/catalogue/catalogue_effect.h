// The catalogue's effects on the twin's side, one file per effect under
// simulation/catalogue/ (registered in simulation/effects.cc, in the
// report's order): its catalogue row (report name, meaning, explanation,
// parameters with units, scales and floors), the --effects keys it owns
// and the field of sim::Effects each sets, the parameters its truth file
// states, when it is on, and its parameters in the twin's plant
// (PlantModel; the equations that use them are plant.{h,cc}'s, and an
// effect acting on the bench's sensors or timing is bench.cc's and
// replay.cc's); the diagnosis' side of the same effect is one file under
// diagnosis/effects/.
#ifndef FLUXCAL_SIMULATION_CATALOGUE_CATALOGUE_EFFECT_H_
#define FLUXCAL_SIMULATION_CATALOGUE_CATALOGUE_EFFECT_H_

#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "simulation/effects.h"
#include "simulation/plant.h"

namespace fluxcal::sim {

// One --effects key and the field of Effects it sets (exactly one of the
// three members is set), and the values the twin can apply: at least
// `min` (above it when `above`), e.g. no negative delay (the bench would
// read commands not yet computed) and no zero DC-link gain (it divides).
struct EffectKey {
  std::string_view name;
  double Effects::*value = nullptr;
  std::optional<double> Effects::*optional = nullptr;   // a true value the manifest keeps nominal
  int Effects::*integer = nullptr;
  double min = -std::numeric_limits<double>::infinity();
  bool above = false;
};

struct CatalogueEffect {
  EffectRow row;
  std::vector<EffectKey> keys;
  // The parameters the truth file states for the effect.
  std::map<std::string, double> (*truth)(const Effects& e) = nullptr;
  // On; nullptr: any catalogue parameter of the truth away from its
  // neutral value.
  bool (*active)(const Effects& e) = nullptr;
  // Its parameters in the plant the twin integrates, the bench's and the
  // replays' alike (nullptr: the motor's own values carry it, MakePlant).
  void (*plant)(const Effects& e, PlantModel* m) = nullptr;
  // The bench's sensors: what the phase current sensors read of the true
  // currents before noise and quantisation (applied in the registry's
  // order: gains before offsets), what the angle sensor adds to the true
  // electrical angle, and what the torque transducer reads less than the
  // air-gap torque at a speed.
  void (*sense)(const Effects& e, double* ia, double* ib, double* ic) = nullptr;
  double (*angle_error)(const Effects& e, double theta_true_rad) = nullptr;
  double (*torque_loss)(const Effects& e, double speed_rpm) = nullptr;
};

// One per file under simulation/catalogue/.
CatalogueEffect DeadTimeEffect();
CatalogueEffect CrossSaturationEffect();
CatalogueEffect StatorResistanceEffect();
CatalogueEffect HfResistanceEffect();
CatalogueEffect DifferentialInductanceEffect();
CatalogueEffect PositionOffsetEffect();
CatalogueEffect CurrentSensorGainEffect();
CatalogueEffect MagnetTemperatureEffect();
CatalogueEffect SamplingDelayEffect();
CatalogueEffect SpatialHarmonicsEffect();
CatalogueEffect CurrentSensorOffsetEffect();
CatalogueEffect DcLinkSenseGainEffect();
CatalogueEffect PhaseResistanceImbalanceEffect();
CatalogueEffect StatorTemperatureDriftEffect();
CatalogueEffect InverterVoltageDropEffect();
CatalogueEffect PositionSensorHarmonicEffect();
CatalogueEffect IronLossEffect();
CatalogueEffect TorqueLossEffect();

// Every catalogue effect, in the report's order.
const std::vector<CatalogueEffect>& CatalogueEffects();
// Every effect's plant hook applied to m.
void ApplyEffectsToPlant(const Effects& e, PlantModel* m);
// Every effect's sensor hook applied to the phase currents.
void SenseCurrents(const Effects& e, double* ia, double* ib, double* ic);
// What the torque transducer reads below the air-gap torque, N m.
double TorqueReadingLoss(const Effects& e, double speed_rpm);

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_CATALOGUE_CATALOGUE_EFFECT_H_
