// Small readers of the exported table formats, one per format and written
// for the tests (CSV, JSON, DCM, CDFX with tinyxml2, the C header by
// pattern), so that a format is checked by what another program reads in
// it, not by the writer's own code. Used by the round-trip test (all
// formats carry the same table) and the A2L cross-check.
#ifndef FLUXCAL_TESTS_TABLES_EXPORT_READERS_H_
#define FLUXCAL_TESTS_TABLES_EXPORT_READERS_H_

#include <map>
#include <set>
#include <string>
#include <vector>

#include "tables/tables.h"

namespace fluxcal::tables::readers {

// What a reader gets out of one exported file. Names are local (the field
// name, "id_a"); `labels` holds them as written.
struct Parsed {
  std::map<std::string, double> scalars;
  std::map<std::string, std::string> text;
  std::vector<std::string> axis_names;
  std::vector<std::vector<double>> axes;
  std::map<std::string, std::vector<double>> arrays;   // outputs and flags, X (first axis) slowest
  std::string payload_crc32, payload_sha256;
  // CDFX and DCM: the unit of each scalar, output and flag, and of the axes
  // in order; the category (CDFX) or block keyword (DCM) of each label.
  std::map<std::string, std::string> units;
  std::vector<std::string> axis_units;
  std::map<std::string, std::string> kinds;
  // Every label / identifier the file defines, as written: CDFX
  // SHORT-NAMEs, DCM block names; C header macros and variables.
  std::set<std::string> labels;
  // C header: the element type of each array (axes included, local names)
  // and the LSB each fixed-point array states (<NAME>_LSB).
  std::map<std::string, std::string> element_types;
  std::map<std::string, double> lsb;
};

// "FLUXCAL_FW_ID_A" -> "id_a".
std::string Local(const Table& t, const std::string& ident);
// The table as every reader should find it.
Parsed Expected(const Table& t);
Parsed ParseCsv(const std::string& bytes);
Parsed ParseJson(const std::string& bytes);
Parsed ParseDcm(const Table& t, const std::string& bytes);
Parsed ParseCdfx(const Table& t, const std::string& bytes);
// Fixed-point arrays are read as their integers (raw values).
Parsed ParseCHeader(const Table& t, const std::string& bytes);

}  // namespace fluxcal::tables::readers

#endif  // FLUXCAL_TESTS_TABLES_EXPORT_READERS_H_
