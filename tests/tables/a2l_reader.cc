// The strict ASAP2 reader (a2l_reader.h). The keyword table below is the
// standard's keyword reference for the blocks covered (ASAM MCD-2 MC 1.6 /
// 1.7, "keyword reference": positional parameters in order, then the
// optional keywords and blocks each may contain).
#include "tests/tables/a2l_reader.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace fluxcal::a2l_reader {
namespace {

// ---------------------------------------------------------------- tokens

class Lexer {
 public:
  Lexer(std::string_view text, std::string_view file) : s_(text), file_(file) {}

  absl::StatusOr<std::vector<Token>> Run() {
    std::vector<Token> out;
    while (true) {
      if (auto st = SkipSpaceAndComments(); !st.ok()) return st;
      if (p_ >= s_.size()) break;
      const char c = s_[p_];
      Token t;
      t.line = line_;
      if (c == '/') {
        const std::string_view rest = s_.substr(p_);
        size_t n = 0;
        if (rest.substr(0, 6) == "/begin") { t.kind = Token::kBegin; n = 6; }
        else if (rest.substr(0, 4) == "/end") { t.kind = Token::kEnd; n = 4; }
        if (n == 0 || (p_ + n < s_.size() && IsIdentChar(s_[p_ + n]))) {
          return Error(line_, absl::StrCat("unexpected '", Word(), "': expected /begin, /end or a comment"));
        }
        t.text = std::string(rest.substr(0, n));
        p_ += n;
      } else if (c == '"') {
        auto st = String(&t);
        if (!st.ok()) return st;
      } else if (std::isdigit(static_cast<unsigned char>(c)) || c == '+' || c == '-' || c == '.') {
        auto st = Number(&t);
        if (!st.ok()) return st;
      } else if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') {
        t.kind = Token::kIdent;
        const size_t b = p_;
        while (p_ < s_.size() && IsIdentChar(s_[p_])) ++p_;
        t.text = std::string(s_.substr(b, p_ - b));
      } else {
        return Error(line_, absl::StrCat("unexpected character '", std::string(1, c), "'"));
      }
      out.push_back(std::move(t));
    }
    return out;
  }

 private:
  // ASAP2 identifiers: a letter or '_', then letters, digits, '_', '.',
  // and the '[' ']' of array element names.
  static bool IsIdentChar(char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '[' || c == ']';
  }

  absl::Status Error(int line, const std::string& what) const {
    return absl::InvalidArgumentError(absl::StrCat(file_, ":", line, ": ", what));
  }

  std::string Word() const {
    size_t e = p_;
    while (e < s_.size() && !std::isspace(static_cast<unsigned char>(s_[e])) && e - p_ < 24) ++e;
    return std::string(s_.substr(p_, e - p_));
  }

  absl::Status SkipSpaceAndComments() {
    while (p_ < s_.size()) {
      const char c = s_[p_];
      if (c == '\n') { ++line_; ++p_; continue; }
      if (std::isspace(static_cast<unsigned char>(c))) { ++p_; continue; }
      if (c == '/' && p_ + 1 < s_.size() && s_[p_ + 1] == '*') {
        const int start = line_;
        p_ += 2;
        while (p_ + 1 < s_.size() && !(s_[p_] == '*' && s_[p_ + 1] == '/')) {
          if (s_[p_] == '\n') ++line_;
          ++p_;
        }
        if (p_ + 1 >= s_.size()) return Error(start, "comment /* not closed");
        p_ += 2;
        continue;
      }
      if (c == '/' && p_ + 1 < s_.size() && s_[p_ + 1] == '/') {
        while (p_ < s_.size() && s_[p_] != '\n') ++p_;
        continue;
      }
      break;
    }
    return absl::OkStatus();
  }

  // "..." on one line; \" \\ \n \t \r escapes (ASAP2 1.6 on) and a doubled
  // quote "" (earlier versions) stand for the character.
  absl::Status String(Token* t) {
    t->kind = Token::kString;
    ++p_;
    while (true) {
      if (p_ >= s_.size() || s_[p_] == '\n') return Error(t->line, "string not closed on its line");
      const char c = s_[p_++];
      if (c == '"') {
        if (p_ < s_.size() && s_[p_] == '"') { t->text += '"'; ++p_; continue; }
        break;
      }
      if (c == '\\') {
        if (p_ >= s_.size()) return Error(t->line, "string not closed on its line");
        const char e = s_[p_++];
        switch (e) {
          case '"': t->text += '"'; break;
          case '\\': t->text += '\\'; break;
          case 'n': t->text += '\n'; break;
          case 't': t->text += '\t'; break;
          case 'r': t->text += '\r'; break;
          default: return Error(t->line, absl::StrCat("unknown escape \\", std::string(1, e), " in a string"));
        }
        continue;
      }
      t->text += c;
    }
    return absl::OkStatus();
  }

  // [+-] (0x hex | digits [. digits] [e [+-] digits] | . digits ...), then
  // a delimiter.
  absl::Status Number(Token* t) {
    t->kind = Token::kNumber;
    const size_t b = p_;
    if (s_[p_] == '+' || s_[p_] == '-') ++p_;
    auto digits = [&](auto pred) {
      const size_t d = p_;
      while (p_ < s_.size() && pred(static_cast<unsigned char>(s_[p_]))) ++p_;
      return p_ - d;
    };
    auto dec = [](unsigned char c) { return std::isdigit(c) != 0; };
    bool ok = false;
    if (p_ + 1 < s_.size() && s_[p_] == '0' && (s_[p_ + 1] == 'x' || s_[p_ + 1] == 'X')) {
      p_ += 2;
      ok = digits([](unsigned char c) { return std::isxdigit(c) != 0; }) > 0;
      t->integer = true;
    } else {
      const size_t int_digits = digits(dec);
      size_t frac_digits = 0;
      bool real = false;
      if (p_ < s_.size() && s_[p_] == '.') { ++p_; frac_digits = digits(dec); real = true; }
      ok = int_digits + frac_digits > 0;
      if (ok && p_ < s_.size() && (s_[p_] == 'e' || s_[p_] == 'E')) {
        ++p_;
        if (p_ < s_.size() && (s_[p_] == '+' || s_[p_] == '-')) ++p_;
        ok = digits(dec) > 0;
        real = true;
      }
      t->integer = !real;
    }
    t->text = std::string(s_.substr(b, p_ - b));
    if (!ok || (p_ < s_.size() && (IsIdentChar(s_[p_]) || s_[p_] == '"'))) {
      while (p_ < s_.size() && !std::isspace(static_cast<unsigned char>(s_[p_]))) ++p_;
      return Error(t->line, absl::StrCat("malformed number '", std::string(s_.substr(b, p_ - b)), "'"));
    }
    if (t->integer) {
      const bool neg = t->text[0] == '-';
      const std::string body = t->text.substr(t->text[0] == '-' || t->text[0] == '+' ? 1 : 0);
      const bool hex = body.size() > 1 && (body[1] == 'x' || body[1] == 'X');
      const double v = static_cast<double>(std::strtoull(body.c_str() + (hex ? 2 : 0), nullptr, hex ? 16 : 10));
      t->number = neg ? -v : v;
    } else {
      t->number = std::strtod(t->text.c_str(), nullptr);
    }
    return absl::OkStatus();
  }

  std::string_view s_;
  std::string file_;
  size_t p_ = 0;
  int line_ = 1;
};

// ------------------------------------------------------- keyword table

enum class P { kIdent, kString, kInt, kNumber, kEnum };
struct Param {
  const char* name;
  P type;
  std::vector<std::string> choices = {};   // kEnum
};
struct KeywordSpec {
  const char* keyword;
  std::vector<Param> params;
  bool repeatable = false;
};
struct ChildSpec {
  const char* keyword;
  int max = -1;   // -1: any number
  int min = 0;
};
struct BlockSpec {
  std::vector<Param> fields;        // positional, in the standard's order
  bool variadic_strings = false;    // ANNOTATION_TEXT: any number of strings
  std::vector<KeywordSpec> options;
  std::vector<ChildSpec> children;
};

const std::vector<std::string> kDatatype = {"UBYTE", "SBYTE", "UWORD", "SWORD", "ULONG", "SLONG",
                                            "A_UINT64", "A_INT64", "FLOAT16_IEEE", "FLOAT32_IEEE", "FLOAT64_IEEE"};
const std::vector<std::string> kByteOrder = {"LITTLE_ENDIAN", "BIG_ENDIAN", "MSB_LAST", "MSB_FIRST",
                                             "MSB_FIRST_MSW_LAST", "MSB_LAST_MSW_FIRST"};
const std::vector<std::string> kIndexMode = {"ALTERNATE_CURVES", "ALTERNATE_WITH_X", "ALTERNATE_WITH_Y", "COLUMN_DIR",
                                             "ROW_DIR"};
const std::vector<std::string> kAddrType = {"PBYTE", "PWORD", "PLONG", "PLONGLONG", "DIRECT"};
const std::vector<std::string> kIndexOrder = {"INDEX_INCR", "INDEX_DECR"};
const std::vector<std::string> kMonotony = {"MON_DECREASE", "MON_INCREASE", "STRICT_DECREASE", "STRICT_INCREASE",
                                            "MONOTONOUS", "STRICT_MON", "NOT_MON"};
const std::vector<std::string> kAccess = {"CALIBRATION", "NO_CALIBRATION", "NOT_IN_MCD_SYSTEM", "OFFLINE_CALIBRATION"};
const std::vector<std::string> kDepositMode = {"ABSOLUTE", "DIFFERENCE"};

std::vector<KeywordSpec> Alignments() {
  std::vector<KeywordSpec> v;
  for (const char* k : {"ALIGNMENT_BYTE", "ALIGNMENT_WORD", "ALIGNMENT_LONG", "ALIGNMENT_INT64",
                        "ALIGNMENT_FLOAT16_IEEE", "ALIGNMENT_FLOAT32_IEEE", "ALIGNMENT_FLOAT64_IEEE"}) {
    v.push_back({k, {{"AlignmentBorder", P::kInt}}});
  }
  return v;
}

std::vector<KeywordSpec> Join(std::vector<KeywordSpec> a, const std::vector<KeywordSpec>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

const std::map<std::string, BlockSpec>& Grammar() {
  static const auto* g = [] {
    auto* m = new std::map<std::string, BlockSpec>;
    const KeywordSpec byte_order{"BYTE_ORDER", {{"ByteOrder", P::kEnum, kByteOrder}}};
    const KeywordSpec access{"CALIBRATION_ACCESS", {{"Type", P::kEnum, kAccess}}};
    const KeywordSpec deposit{"DEPOSIT", {{"Mode", P::kEnum, kDepositMode}}};
    const KeywordSpec display{"DISPLAY_IDENTIFIER", {{"DisplayName", P::kIdent}}};
    const KeywordSpec ext{"ECU_ADDRESS_EXTENSION", {{"Extension", P::kInt}}};
    const KeywordSpec ext_limits{"EXTENDED_LIMITS", {{"LowerLimit", P::kNumber}, {"UpperLimit", P::kNumber}}};
    const KeywordSpec format{"FORMAT", {{"FormatString", P::kString}}};
    const KeywordSpec guard{"GUARD_RAILS", {}};
    const KeywordSpec monotony{"MONOTONY", {{"Monotony", P::kEnum, kMonotony}}};
    const KeywordSpec phys_unit{"PHYS_UNIT", {{"Unit", P::kString}}};
    const KeywordSpec read_only{"READ_ONLY", {}};
    const KeywordSpec step{"STEP_SIZE", {{"StepSize", P::kNumber}}};
    const KeywordSpec symbol{"SYMBOL_LINK", {{"SymbolName", P::kString}, {"Offset", P::kInt}}};

    (*m)[""] = {{}, false,
                {{"ASAP2_VERSION", {{"VersionNo", P::kInt}, {"UpgradeNo", P::kInt}}},
                 {"A2ML_VERSION", {{"VersionNo", P::kInt}, {"UpgradeNo", P::kInt}}}},
                {{"PROJECT", 1, 1}}};
    (*m)["PROJECT"] = {{{"Name", P::kIdent}, {"LongIdentifier", P::kString}}, false, {},
                       {{"HEADER", 1}, {"MODULE"}}};
    (*m)["HEADER"] = {{{"Comment", P::kString}}, false,
                      {{"VERSION", {{"VersionIdentifier", P::kString}}}, {"PROJECT_NO", {{"ProjectNumber", P::kIdent}}}},
                      {}};
    (*m)["MODULE"] = {{{"Name", P::kIdent}, {"LongIdentifier", P::kString}}, false, {},
                      {{"MOD_PAR", 1}, {"MOD_COMMON", 1}, {"COMPU_METHOD"}, {"RECORD_LAYOUT"}, {"AXIS_PTS"},
                       {"CHARACTERISTIC"}}};
    (*m)["MOD_PAR"] = {{{"Comment", P::kString}}, false,
                       {{"VERSION", {{"VersionIdentifier", P::kString}}},
                        {"ADDR_EPK", {{"Address", P::kInt}}, true},
                        {"EPK", {{"Identifier", P::kString}}},
                        {"SUPPLIER", {{"Manufacturer", P::kString}}},
                        {"CUSTOMER", {{"Customer", P::kString}}},
                        {"CUSTOMER_NO", {{"Number", P::kString}}},
                        {"USER", {{"UserName", P::kString}}},
                        {"PHONE_NO", {{"TelNum", P::kString}}},
                        {"ECU", {{"ControlUnit", P::kString}}},
                        {"CPU_TYPE", {{"CPU", P::kString}}},
                        {"NO_OF_INTERFACES", {{"Num", P::kInt}}},
                        {"ECU_CALIBRATION_OFFSET", {{"Offset", P::kInt}}},
                        {"SYSTEM_CONSTANT", {{"Name", P::kString}, {"Value", P::kString}}, true}},
                       {}};
    (*m)["MOD_COMMON"] = {{{"Comment", P::kString}}, false,
                          Join({byte_order, deposit, {"DATA_SIZE", {{"Size", P::kInt}}}}, Alignments()),
                          {}};
    (*m)["COMPU_METHOD"] = {
        {{"Name", P::kIdent},
         {"LongIdentifier", P::kString},
         {"ConversionType", P::kEnum, {"IDENTICAL", "FORM", "LINEAR", "RAT_FUNC", "TAB_INTP", "TAB_NOINTP", "TAB_VERB"}},
         {"Format", P::kString},
         {"Unit", P::kString}},
        false,
        {{"COEFFS",
          {{"a", P::kNumber}, {"b", P::kNumber}, {"c", P::kNumber}, {"d", P::kNumber}, {"e", P::kNumber},
           {"f", P::kNumber}}},
         {"COEFFS_LINEAR", {{"a", P::kNumber}, {"b", P::kNumber}}},
         {"COMPU_TAB_REF", {{"ConversionTable", P::kIdent}}},
         {"REF_UNIT", {{"Unit", P::kIdent}}},
         {"STATUS_STRING_REF", {{"ConversionTable", P::kIdent}}}},
        {}};
    const std::vector<Param> axis_pts_xy = {{"Position", P::kInt}, {"Datatype", P::kEnum, kDatatype},
                                            {"IndexIncr", P::kEnum, kIndexOrder}, {"Addressing", P::kEnum, kAddrType}};
    (*m)["RECORD_LAYOUT"] = {
        {{"Name", P::kIdent}},
        false,
        Join({{"FNC_VALUES",
               {{"Position", P::kInt}, {"Datatype", P::kEnum, kDatatype}, {"IndexMode", P::kEnum, kIndexMode},
                {"AddressType", P::kEnum, kAddrType}}},
              {"AXIS_PTS_X", axis_pts_xy},
              {"AXIS_PTS_Y", axis_pts_xy},
              {"NO_AXIS_PTS_X", {{"Position", P::kInt}, {"Datatype", P::kEnum, kDatatype}}},
              {"NO_AXIS_PTS_Y", {{"Position", P::kInt}, {"Datatype", P::kEnum, kDatatype}}},
              {"FIX_NO_AXIS_PTS_X", {{"NumberOfAxisPoints", P::kInt}}},
              {"FIX_NO_AXIS_PTS_Y", {{"NumberOfAxisPoints", P::kInt}}},
              {"STATIC_RECORD_LAYOUT", {}}},
             Alignments()),
        {}};
    (*m)["AXIS_PTS"] = {{{"Name", P::kIdent},
                         {"LongIdentifier", P::kString},
                         {"Address", P::kInt},
                         {"InputQuantity", P::kIdent},
                         {"DepositAttr", P::kIdent},
                         {"MaxDiff", P::kNumber},
                         {"Conversion", P::kIdent},
                         {"MaxAxisPoints", P::kInt},
                         {"LowerLimit", P::kNumber},
                         {"UpperLimit", P::kNumber}},
                        false,
                        {byte_order, access, deposit, display, ext, ext_limits, format, guard, monotony, phys_unit,
                         read_only, step, symbol},
                        {{"ANNOTATION"}}};
    (*m)["CHARACTERISTIC"] = {
        {{"Name", P::kIdent},
         {"LongIdentifier", P::kString},
         {"Type", P::kEnum, {"ASCII", "CURVE", "MAP", "CUBOID", "CUBE_4", "CUBE_5", "VAL_BLK", "VALUE"}},
         {"Address", P::kInt},
         {"Deposit", P::kIdent},
         {"MaxDiff", P::kNumber},
         {"Conversion", P::kIdent},
         {"LowerLimit", P::kNumber},
         {"UpperLimit", P::kNumber}},
        false,
        {{"BIT_MASK", {{"Mask", P::kInt}}}, byte_order, access,
         {"COMPARISON_QUANTITY", {{"Name", P::kIdent}}}, {"DISCRETE", {}}, display, ext, ext_limits, format, guard,
         {"NUMBER", {{"Number", P::kInt}}}, phys_unit, read_only, step, symbol},
        {{"AXIS_DESCR"}, {"ANNOTATION"}}};
    (*m)["AXIS_DESCR"] = {
        {{"Attribute", P::kEnum, {"CURVE_AXIS", "COM_AXIS", "FIX_AXIS", "RES_AXIS", "STD_AXIS"}},
         {"InputQuantity", P::kIdent},
         {"Conversion", P::kIdent},
         {"MaxAxisPoints", P::kInt},
         {"LowerLimit", P::kNumber},
         {"UpperLimit", P::kNumber}},
        false,
        {{"AXIS_PTS_REF", {{"AxisPoints", P::kIdent}}}, byte_order, {"CURVE_AXIS_REF", {{"CurveAxis", P::kIdent}}},
         deposit, ext_limits,
         {"FIX_AXIS_PAR", {{"Offset", P::kNumber}, {"Shift", P::kNumber}, {"NumberApo", P::kInt}}},
         {"FIX_AXIS_PAR_DIST", {{"Offset", P::kNumber}, {"Distance", P::kNumber}, {"NumberApo", P::kInt}}}, format,
         {"MAX_GRAD", {{"MaxGradient", P::kNumber}}}, monotony, phys_unit, read_only, step},
        {{"ANNOTATION"}}};
    (*m)["ANNOTATION"] = {{}, false,
                          {{"ANNOTATION_LABEL", {{"Label", P::kString}}}, {"ANNOTATION_ORIGIN", {{"Origin", P::kString}}}},
                          {{"ANNOTATION_TEXT", 1}}};
    (*m)["ANNOTATION_TEXT"] = {{}, true, {}, {}};
    return m;
  }();
  return *g;
}

// ------------------------------------------------------------- grammar

struct Keyword {
  std::string name;
  std::vector<Token> args;
  int line = 0;
};
struct Block {
  std::string keyword;
  int line = 0;
  std::vector<Token> fields;
  std::vector<Keyword> options;
  std::vector<Block> children;

  const Keyword* Option(const std::string& k) const {
    for (const auto& o : options) {
      if (o.name == k) return &o;
    }
    return nullptr;
  }
  std::vector<const Keyword*> Options(const std::string& k) const {
    std::vector<const Keyword*> v;
    for (const auto& o : options) {
      if (o.name == k) v.push_back(&o);
    }
    return v;
  }
  std::vector<const Block*> Children(const std::string& k) const {
    std::vector<const Block*> v;
    for (const auto& c : children) {
      if (c.keyword == k) v.push_back(&c);
    }
    return v;
  }
};

const char* KindName(Token::Kind k) {
  switch (k) {
    case Token::kBegin: return "/begin";
    case Token::kEnd: return "/end";
    case Token::kIdent: return "an identifier";
    case Token::kString: return "a string";
    case Token::kNumber: return "a number";
  }
  return "?";
}

class Parser {
 public:
  Parser(std::vector<Token> tokens, std::string_view file) : t_(std::move(tokens)), file_(file) {}

  absl::StatusOr<Block> Root() {
    Block root;
    root.line = 1;
    if (auto st = Body(Grammar().at(""), "", &root); !st.ok()) return st;
    return root;
  }

 private:
  absl::Status Error(int line, const std::string& what) const {
    return absl::InvalidArgumentError(absl::StrCat(file_, ":", line, ": ", what));
  }
  std::string Describe(const Token& t) const {
    return t.kind == Token::kString ? absl::StrCat("\"", t.text, "\"") : t.text;
  }
  int LastLine() const { return t_.empty() ? 1 : t_.back().line; }

  absl::Status Value(const Param& p, const std::string& where, int where_line, Token* out) {
    if (k_ >= t_.size()) {
      return Error(LastLine(), absl::StrCat(where, " (line ", where_line, "): parameter ", p.name,
                                            " missing at the end of the file"));
    }
    const Token& t = t_[k_];
    bool ok = false;
    std::string expected;
    switch (p.type) {
      case P::kIdent: ok = t.kind == Token::kIdent; expected = "an identifier"; break;
      case P::kString: ok = t.kind == Token::kString; expected = "a string"; break;
      case P::kInt: ok = t.kind == Token::kNumber && t.integer; expected = "an integer"; break;
      case P::kNumber: ok = t.kind == Token::kNumber; expected = "a number"; break;
      case P::kEnum:
        ok = t.kind == Token::kIdent &&
             std::find(p.choices.begin(), p.choices.end(), t.text) != p.choices.end();
        expected = absl::StrCat("one of ", absl::StrJoin(p.choices, " "));
        break;
    }
    if (!ok) {
      return Error(t.line, absl::StrCat(where, " (line ", where_line, "): parameter ", p.name, ": expected ", expected,
                                        ", got ", KindName(t.kind), " '", Describe(t), "'"));
    }
    *out = t;
    ++k_;
    return absl::OkStatus();
  }

  // After "/begin KEYWORD": the positional fields, then optional keywords
  // and child blocks up to "/end KEYWORD" (the root: up to the end).
  absl::Status Body(const BlockSpec& spec, const std::string& kw, Block* b) {
    const std::string where = kw.empty() ? "file" : absl::StrCat("/begin ", kw);
    for (const auto& p : spec.fields) {
      Token v;
      if (auto st = Value(p, where, b->line, &v); !st.ok()) return st;
      b->fields.push_back(v);
    }
    if (spec.variadic_strings) {
      while (k_ < t_.size() && t_[k_].kind == Token::kString) b->fields.push_back(t_[k_++]);
    }
    std::map<std::string, int> counts;
    while (true) {
      if (k_ >= t_.size()) {
        if (!kw.empty()) return Error(b->line, absl::StrCat("/begin ", kw, " is not closed by /end ", kw));
        break;
      }
      const Token& t = t_[k_];
      if (t.kind == Token::kEnd) {
        if (kw.empty()) return Error(t.line, "/end without a /begin");
        ++k_;
        if (k_ >= t_.size() || t_[k_].kind != Token::kIdent) {
          return Error(t.line, absl::StrCat("/end without a keyword (closing /begin ", kw, " of line ", b->line, ")"));
        }
        if (t_[k_].text != kw) {
          return Error(t.line, absl::StrCat("/end ", t_[k_].text, " does not close /begin ", kw, " of line ", b->line));
        }
        ++k_;
        break;
      }
      if (t.kind == Token::kBegin) {
        ++k_;
        if (k_ >= t_.size() || t_[k_].kind != Token::kIdent) return Error(t.line, "/begin without a keyword");
        const std::string child = t_[k_].text;
        const auto cs = std::find_if(spec.children.begin(), spec.children.end(),
                                     [&](const ChildSpec& c) { return child == c.keyword; });
        if (cs == spec.children.end()) {
          return Error(t.line, absl::StrCat("/begin ", child, " is not allowed in ", where,
                                            kw.empty() ? "" : absl::StrCat(" (line ", b->line, ")"),
                                            Grammar().count(child) ? "" : " (not a block this reader knows)"));
        }
        if (cs->max >= 0 && ++counts[child] > cs->max) {
          return Error(t.line, absl::StrCat("/begin ", child, ": at most ", cs->max, " in ", where));
        }
        ++k_;
        Block c;
        c.keyword = child;
        c.line = t.line;
        if (auto st = Body(Grammar().at(child), child, &c); !st.ok()) return st;
        b->children.push_back(std::move(c));
        continue;
      }
      if (t.kind != Token::kIdent) {
        return Error(t.line, absl::StrCat("unexpected ", KindName(t.kind), " '", Describe(t), "' in ", where,
                                          kw.empty() ? "" : absl::StrCat(" (line ", b->line, ")"),
                                          ": only keywords and blocks follow the positional parameters"));
      }
      const auto os = std::find_if(spec.options.begin(), spec.options.end(),
                                   [&](const KeywordSpec& o) { return t.text == o.keyword; });
      if (os == spec.options.end()) {
        return Error(t.line, absl::StrCat("unknown keyword ", t.text, " in ", where,
                                          kw.empty() ? "" : absl::StrCat(" (line ", b->line, ")")));
      }
      if (!os->repeatable && counts[t.text]++ > 0) {
        return Error(t.line, absl::StrCat("keyword ", t.text, " given twice in ", where));
      }
      Keyword k;
      k.name = t.text;
      k.line = t.line;
      ++k_;
      for (const auto& p : os->params) {
        Token v;
        if (auto st = Value(p, t.text, t.line, &v); !st.ok()) return st;
        k.args.push_back(v);
      }
      b->options.push_back(std::move(k));
    }
    for (const auto& c : spec.children) {
      if (c.min > 0 && static_cast<int>(b->Children(c.keyword).size()) < c.min) {
        return Error(b->line, absl::StrCat(where, ": /begin ", c.keyword, " missing"));
      }
    }
    return absl::OkStatus();
  }

  std::vector<Token> t_;
  std::string file_;
  size_t k_ = 0;
};

// ---------------------------------------------------------- references

std::vector<Annotation> Annotations(const Block& b) {
  std::vector<Annotation> out;
  for (const Block* a : b.Children("ANNOTATION")) {
    Annotation x;
    if (const Keyword* k = a->Option("ANNOTATION_LABEL")) x.label = k->args[0].text;
    if (const Keyword* k = a->Option("ANNOTATION_ORIGIN")) x.origin = k->args[0].text;
    for (const Block* t : a->Children("ANNOTATION_TEXT")) {
      for (const auto& s : t->fields) x.text.push_back(s.text);
    }
    out.push_back(std::move(x));
  }
  return out;
}

void Symbol(const Block& b, std::string* name, int64_t* offset) {
  if (const Keyword* k = b.Option("SYMBOL_LINK")) {
    *name = k->args[0].text;
    *offset = static_cast<int64_t>(k->args[1].number);
  }
}

absl::StatusOr<Module> BuildModule(const Block& m, const std::string& file) {
  auto error = [&](int line, const std::string& what) {
    return absl::InvalidArgumentError(absl::StrCat(file, ":", line, ": ", what));
  };
  Module out;
  out.name = m.fields[0].text;
  out.long_identifier = m.fields[1].text;
  for (const Block* p : m.Children("MOD_PAR")) {
    out.mod_par_comment = p->fields[0].text;
    if (const Keyword* k = p->Option("VERSION")) out.version = k->args[0].text;
    for (const Keyword* k : p->Options("SYSTEM_CONSTANT")) out.system_constants.push_back({k->args[0].text, k->args[1].text});
  }
  for (const Block* c : m.Children("MOD_COMMON")) {
    if (const Keyword* k = c->Option("BYTE_ORDER")) out.byte_order = k->args[0].text;
    if (const Keyword* k = c->Option("DEPOSIT")) out.deposit = k->args[0].text;
    for (const auto& o : c->options) {
      if (o.name.rfind("ALIGNMENT_", 0) == 0) out.alignments[o.name] = static_cast<int>(o.args[0].number);
    }
  }
  // Names: COMPU_METHODs and RECORD_LAYOUTs each unique; CHARACTERISTIC
  // and AXIS_PTS names unique across both (one namespace of objects).
  for (const Block* b : m.Children("COMPU_METHOD")) {
    CompuMethod c;
    c.name = b->fields[0].text;
    c.long_identifier = b->fields[1].text;
    c.conversion_type = b->fields[2].text;
    c.format = b->fields[3].text;
    c.unit = b->fields[4].text;
    c.line = b->line;
    // Format "%Length.Layout".
    const std::string& f = c.format;
    const size_t dot = f.find('.');
    auto all_digits = [](const std::string& s) {
      return !s.empty() && std::all_of(s.begin(), s.end(), [](char x) { return std::isdigit(static_cast<unsigned char>(x)); });
    };
    if (f.size() < 4 || f[0] != '%' || dot == std::string::npos || !all_digits(f.substr(1, dot - 1)) ||
        !all_digits(f.substr(dot + 1))) {
      return error(b->line, absl::StrCat("COMPU_METHOD ", c.name, ": Format '", f, "' is not %Length.Layout"));
    }
    if (const Keyword* k = b->Option("COEFFS")) for (const auto& a : k->args) c.coeffs.push_back(a.number);
    if (const Keyword* k = b->Option("COEFFS_LINEAR")) for (const auto& a : k->args) c.coeffs_linear.push_back(a.number);
    if (c.conversion_type == "RAT_FUNC" && c.coeffs.empty()) {
      return error(b->line, absl::StrCat("COMPU_METHOD ", c.name, ": RAT_FUNC without COEFFS"));
    }
    if (c.conversion_type == "LINEAR" && c.coeffs_linear.empty()) {
      return error(b->line, absl::StrCat("COMPU_METHOD ", c.name, ": LINEAR without COEFFS_LINEAR"));
    }
    if (!out.compu_methods.emplace(c.name, c).second) {
      return error(b->line, absl::StrCat("COMPU_METHOD ", c.name, " defined twice"));
    }
  }
  for (const Block* b : m.Children("RECORD_LAYOUT")) {
    RecordLayout r;
    r.name = b->fields[0].text;
    r.line = b->line;
    if (const Keyword* k = b->Option("FNC_VALUES")) {
      r.fnc_position = static_cast<int>(k->args[0].number);
      r.fnc_datatype = k->args[1].text;
      r.fnc_index_mode = k->args[2].text;
      r.fnc_address_type = k->args[3].text;
    }
    if (const Keyword* k = b->Option("AXIS_PTS_X")) {
      r.axis_position = static_cast<int>(k->args[0].number);
      r.axis_datatype = k->args[1].text;
      r.axis_index_incr = k->args[2].text;
      r.axis_addressing = k->args[3].text;
    }
    if (!out.record_layouts.emplace(r.name, r).second) {
      return error(b->line, absl::StrCat("RECORD_LAYOUT ", r.name, " defined twice"));
    }
  }
  std::set<std::string> objects;
  auto conversion_ok = [&](const std::string& c, bool ascii) {
    return out.compu_methods.count(c) > 0 || (ascii && c == "NO_COMPU_METHOD");
  };
  for (const Block* b : m.Children("AXIS_PTS")) {
    AxisPts a;
    a.name = b->fields[0].text;
    a.long_identifier = b->fields[1].text;
    a.address = static_cast<uint64_t>(b->fields[2].number);
    a.input_quantity = b->fields[3].text;
    a.deposit = b->fields[4].text;
    a.max_diff = b->fields[5].number;
    a.conversion = b->fields[6].text;
    a.max_axis_points = static_cast<int>(b->fields[7].number);
    a.lower_limit = b->fields[8].number;
    a.upper_limit = b->fields[9].number;
    a.line = b->line;
    Symbol(*b, &a.symbol_link, &a.symbol_offset);
    if (const Keyword* k = b->Option("MONOTONY")) a.monotony = k->args[0].text;
    a.read_only = b->Option("READ_ONLY") != nullptr;
    a.annotations = Annotations(*b);
    if (!objects.insert(a.name).second) return error(b->line, absl::StrCat("AXIS_PTS ", a.name, ": name used twice"));
    const auto rl = out.record_layouts.find(a.deposit);
    if (rl == out.record_layouts.end()) {
      return error(b->fields[4].line, absl::StrCat("AXIS_PTS ", a.name, ": DepositAttr ", a.deposit,
                                                   " is not a RECORD_LAYOUT"));
    }
    if (!rl->second.axis_position) {
      return error(b->fields[4].line, absl::StrCat("AXIS_PTS ", a.name, ": RECORD_LAYOUT ", a.deposit,
                                                   " has no AXIS_PTS_X"));
    }
    if (!conversion_ok(a.conversion, false)) {
      return error(b->fields[6].line, absl::StrCat("AXIS_PTS ", a.name, ": Conversion ", a.conversion,
                                                   " is not a COMPU_METHOD"));
    }
    if (a.max_axis_points < 1 || a.lower_limit > a.upper_limit) {
      return error(b->line, absl::StrCat("AXIS_PTS ", a.name, ": MaxAxisPoints < 1 or LowerLimit > UpperLimit"));
    }
    out.axis_pts.push_back(std::move(a));
  }
  for (const Block* b : m.Children("CHARACTERISTIC")) {
    Characteristic c;
    c.name = b->fields[0].text;
    c.long_identifier = b->fields[1].text;
    c.type = b->fields[2].text;
    c.address = static_cast<uint64_t>(b->fields[3].number);
    c.deposit = b->fields[4].text;
    c.max_diff = b->fields[5].number;
    c.conversion = b->fields[6].text;
    c.lower_limit = b->fields[7].number;
    c.upper_limit = b->fields[8].number;
    c.line = b->line;
    Symbol(*b, &c.symbol_link, &c.symbol_offset);
    if (const Keyword* k = b->Option("NUMBER")) c.number = static_cast<int>(k->args[0].number);
    c.read_only = b->Option("READ_ONLY") != nullptr;
    c.annotations = Annotations(*b);
    if (!objects.insert(c.name).second) {
      return error(b->line, absl::StrCat("CHARACTERISTIC ", c.name, ": name used twice"));
    }
    const auto rl = out.record_layouts.find(c.deposit);
    if (rl == out.record_layouts.end()) {
      return error(b->fields[4].line, absl::StrCat("CHARACTERISTIC ", c.name, ": Deposit ", c.deposit,
                                                   " is not a RECORD_LAYOUT"));
    }
    if (!rl->second.fnc_position) {
      return error(b->fields[4].line, absl::StrCat("CHARACTERISTIC ", c.name, ": RECORD_LAYOUT ", c.deposit,
                                                   " has no FNC_VALUES"));
    }
    if (!conversion_ok(c.conversion, c.type == "ASCII")) {
      return error(b->fields[6].line, absl::StrCat("CHARACTERISTIC ", c.name, ": Conversion ", c.conversion,
                                                   " is not a COMPU_METHOD"));
    }
    if (c.lower_limit > c.upper_limit) {
      return error(b->line, absl::StrCat("CHARACTERISTIC ", c.name, ": LowerLimit > UpperLimit"));
    }
    if (c.type == "ASCII" && c.number < 1) {
      return error(b->line, absl::StrCat("CHARACTERISTIC ", c.name, ": ASCII without NUMBER"));
    }
    const size_t want_axes = c.type == "CURVE" ? 1 : c.type == "MAP" ? 2 : c.type == "CUBOID" ? 3 : 0;
    const auto descrs = b->Children("AXIS_DESCR");
    if (descrs.size() != want_axes) {
      return error(b->line, absl::StrCat("CHARACTERISTIC ", c.name, ": ", c.type, " with ", descrs.size(),
                                         " AXIS_DESCR, expected ", want_axes));
    }
    for (const Block* d : descrs) {
      AxisDescr a;
      a.attribute = d->fields[0].text;
      a.input_quantity = d->fields[1].text;
      a.conversion = d->fields[2].text;
      a.max_axis_points = static_cast<int>(d->fields[3].number);
      a.lower_limit = d->fields[4].number;
      a.upper_limit = d->fields[5].number;
      a.line = d->line;
      if (const Keyword* k = d->Option("AXIS_PTS_REF")) a.axis_pts_ref = k->args[0].text;
      if (!conversion_ok(a.conversion, false)) {
        return error(d->fields[2].line, absl::StrCat("AXIS_DESCR of ", c.name, ": Conversion ", a.conversion,
                                                     " is not a COMPU_METHOD"));
      }
      if (a.attribute == "COM_AXIS") {
        if (a.axis_pts_ref.empty()) {
          return error(d->line, absl::StrCat("AXIS_DESCR of ", c.name, ": COM_AXIS without AXIS_PTS_REF"));
        }
        const AxisPts* p = out.FindAxisPts(a.axis_pts_ref);
        if (p == nullptr) {
          return error(d->Option("AXIS_PTS_REF")->line,
                       absl::StrCat("AXIS_DESCR of ", c.name, ": AXIS_PTS_REF ", a.axis_pts_ref, " is not an AXIS_PTS"));
        }
        if (p->max_axis_points != a.max_axis_points) {
          return error(d->line, absl::StrCat("AXIS_DESCR of ", c.name, ": MaxAxisPoints ", a.max_axis_points,
                                             ", its AXIS_PTS ", p->name, " has ", p->max_axis_points));
        }
      }
      c.axes.push_back(std::move(a));
    }
    out.characteristics.push_back(std::move(c));
  }
  return out;
}

}  // namespace

absl::StatusOr<double> CompuMethod::ToPhysical(double raw) const {
  if (conversion_type == "IDENTICAL") return raw;
  if (conversion_type == "LINEAR") return coeffs_linear[0] * raw + coeffs_linear[1];
  if (conversion_type == "RAT_FUNC") {
    const double a = coeffs[0], b = coeffs[1], c = coeffs[2], d = coeffs[3], e = coeffs[4], f = coeffs[5];
    if (a != 0 || d != 0) {
      return absl::UnimplementedError(absl::StrCat("COMPU_METHOD ", name, ": RAT_FUNC of second order"));
    }
    // raw (e p + f) = b p + c  =>  p = (c - f raw) / (e raw - b).
    const double den = e * raw - b;
    if (den == 0) return absl::InvalidArgumentError(absl::StrCat("COMPU_METHOD ", name, ": no inverse at ", raw));
    return (c - f * raw) / den;
  }
  return absl::UnimplementedError(absl::StrCat("COMPU_METHOD ", name, ": ", conversion_type));
}

const AxisPts* Module::FindAxisPts(const std::string& n) const {
  for (const auto& a : axis_pts) {
    if (a.name == n) return &a;
  }
  return nullptr;
}

const Characteristic* Module::FindCharacteristic(const std::string& n) const {
  for (const auto& c : characteristics) {
    if (c.name == n) return &c;
  }
  return nullptr;
}

absl::StatusOr<std::vector<Token>> Tokenize(std::string_view text, std::string_view file) {
  return Lexer(text, file).Run();
}

absl::StatusOr<A2lFile> ReadA2l(std::string_view text, std::string_view file) {
  auto tokens = Tokenize(text, file);
  if (!tokens.ok()) return tokens.status();
  auto root = Parser(*std::move(tokens), file).Root();
  if (!root.ok()) return root.status();
  A2lFile out;
  if (const Keyword* k = root->Option("ASAP2_VERSION")) {
    out.version_no = static_cast<int>(k->args[0].number);
    out.upgrade_no = static_cast<int>(k->args[1].number);
  }
  const Block& project = *root->Children("PROJECT").at(0);
  out.project_name = project.fields[0].text;
  out.project_long_identifier = project.fields[1].text;
  for (const Block* h : project.Children("HEADER")) {
    out.header_comment = h->fields[0].text;
    if (const Keyword* k = h->Option("VERSION")) out.header_version = k->args[0].text;
  }
  for (const Block* m : project.Children("MODULE")) {
    auto module = BuildModule(*m, std::string(file));
    if (!module.ok()) return module.status();
    out.modules.push_back(*std::move(module));
  }
  return out;
}

}  // namespace fluxcal::a2l_reader
