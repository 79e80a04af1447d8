// A strict reader of the ASAM MCD-2 MC (ASAP2) description language, for
// tests only. It is written apart from fluxcal's A2L writer (tables/a2l.cc)
// and shares no code with it: its keyword table follows the standard's
// keyword reference (positional parameters in the standard's order, then
// the optional keywords a block may hold), so that a writer error is not
// repeated by the reader. It covers the blocks a calibration table needs
// (PROJECT, HEADER, MODULE, MOD_PAR, MOD_COMMON, COMPU_METHOD,
// RECORD_LAYOUT, AXIS_PTS, CHARACTERISTIC, AXIS_DESCR, ANNOTATION,
// ANNOTATION_TEXT) and rejects any other block or keyword.
//
// Three levels, each failing with InvalidArgument "FILE:LINE: ...":
//   tokens     strings ("..." with \" \\ \n \t escapes or a doubled quote),
//              comments /* */ and //, identifiers, decimal, float and hex
//              numbers, /begin and /end;
//   grammar    /begin KEYWORD ... /end KEYWORD nesting, each block's
//              positional fields by type, its optional keywords with their
//              parameters (once unless repeatable), its child blocks;
//   references every Deposit names a RECORD_LAYOUT, every Conversion a
//              COMPU_METHOD (or NO_COMPU_METHOD), every AXIS_PTS_REF an
//              AXIS_PTS of as many points, names unique; a CURVE has one
//              AXIS_DESCR, a MAP two, an ASCII a NUMBER.
#ifndef FLUXCAL_TESTS_TABLES_A2L_READER_H_
#define FLUXCAL_TESTS_TABLES_A2L_READER_H_

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"

namespace fluxcal::a2l_reader {

struct Token {
  enum Kind { kBegin, kEnd, kIdent, kString, kNumber };
  Kind kind = kIdent;
  std::string text;     // identifier, string contents (unescaped) or the number as written
  double number = 0;    // kNumber
  bool integer = false; // kNumber written without '.' or exponent (decimal or hex)
  int line = 0;
};
absl::StatusOr<std::vector<Token>> Tokenize(std::string_view text, std::string_view file);

// COMPU_METHOD: internal (raw) to physical.
struct CompuMethod {
  std::string name, long_identifier, conversion_type, format, unit;
  std::vector<double> coeffs;          // RAT_FUNC: a b c d e f
  std::vector<double> coeffs_linear;   // LINEAR: a b
  int line = 0;
  // IDENTICAL: raw; LINEAR: a raw + b; RAT_FUNC (raw = (a p^2 + b p + c) /
  // (d p^2 + e p + f)) solved for p when a = d = 0: p = (c - f raw) /
  // (e raw - b). Unimplemented for other types.
  absl::StatusOr<double> ToPhysical(double raw) const;
};

struct RecordLayout {
  std::string name;
  // FNC_VALUES Position Datatype IndexMode AddressType
  std::optional<int> fnc_position;
  std::string fnc_datatype, fnc_index_mode, fnc_address_type;
  // AXIS_PTS_X Position Datatype IndexIncr Addressing
  std::optional<int> axis_position;
  std::string axis_datatype, axis_index_incr, axis_addressing;
  int line = 0;
};

struct AxisDescr {
  std::string attribute, input_quantity, conversion;
  int max_axis_points = 0;
  double lower_limit = 0, upper_limit = 0;
  std::string axis_pts_ref;
  int line = 0;
};

struct Annotation {
  std::string label, origin;
  std::vector<std::string> text;
};

struct AxisPts {
  std::string name, long_identifier;
  uint64_t address = 0;
  std::string input_quantity, deposit;
  double max_diff = 0;
  std::string conversion;
  int max_axis_points = 0;
  double lower_limit = 0, upper_limit = 0;
  std::string symbol_link, monotony;
  int64_t symbol_offset = 0;
  bool read_only = false;
  std::vector<Annotation> annotations;
  int line = 0;
};

struct Characteristic {
  std::string name, long_identifier, type;
  uint64_t address = 0;
  std::string deposit;
  double max_diff = 0;
  std::string conversion;
  double lower_limit = 0, upper_limit = 0;
  std::vector<AxisDescr> axes;
  std::string symbol_link;
  int64_t symbol_offset = 0;
  int number = 0;   // NUMBER (ASCII length, VAL_BLK count); 0 when absent
  bool read_only = false;
  std::vector<Annotation> annotations;
  int line = 0;
};

struct Module {
  std::string name, long_identifier;
  // MOD_PAR
  std::string mod_par_comment, version;
  std::vector<std::pair<std::string, std::string>> system_constants;
  // MOD_COMMON
  std::string byte_order, deposit;
  std::map<std::string, int> alignments;   // "ALIGNMENT_WORD" -> 2
  std::map<std::string, CompuMethod> compu_methods;
  std::map<std::string, RecordLayout> record_layouts;
  std::vector<AxisPts> axis_pts;                 // in file order
  std::vector<Characteristic> characteristics;   // in file order
  const AxisPts* FindAxisPts(const std::string& name) const;
  const Characteristic* FindCharacteristic(const std::string& name) const;
};

struct A2lFile {
  int version_no = 0, upgrade_no = 0;   // ASAP2_VERSION
  std::string project_name, project_long_identifier, header_comment, header_version;
  std::vector<Module> modules;
};

absl::StatusOr<A2lFile> ReadA2l(std::string_view text, std::string_view file = "a2l");

}  // namespace fluxcal::a2l_reader

#endif  // FLUXCAL_TESTS_TABLES_A2L_READER_H_
