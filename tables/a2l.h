// ASAM MCD-2 MC (ASAP2) 1.71 description of a table as the C header of the
// same --ctype lays it out in ECU memory (docs/tables.md, "A2L"): one
// AXIS_PTS per axis, shared by the outputs and flags (CURVE / MAP with
// COM_AXIS), the scalars as VALUE and the text fields as ASCII
// characteristics, one COMPU_METHOD per quantity and representation, the
// RECORD_LAYOUTs of the C arrays; names are the tables' labels (Label), the
// C variables are given by SYMBOL_LINK at address 0x0.
#ifndef FLUXCAL_TABLES_A2L_H_
#define FLUXCAL_TABLES_A2L_H_

#include <string>
#include <vector>

#include "tables/tables.h"

namespace fluxcal::tables {

// `scales`: QuantityScales(t, ct). The table is checked by Export.
std::string A2lDescription(const Table& t, CType ct, const std::vector<QuantityScale>& scales);

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_A2L_H_
