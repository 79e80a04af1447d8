#include "storage/sql_source.h"

#include <cstdlib>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"

namespace fluxcal::storage {

SqlValue BytesOrNull(const std::string& bytes) {
  return bytes.empty() ? SqlValue(nullptr) : SqlValue(std::vector<uint8_t>(bytes.begin(), bytes.end()));
}

SqlValue TextOrNull(const std::string& text) { return text.empty() ? SqlValue(nullptr) : SqlValue(text); }

int64_t SqlRow::Int(int col) const {
  const SqlValue& v = cells_.at(col);
  if (auto* i = std::get_if<int64_t>(&v)) return *i;
  if (auto* d = std::get_if<double>(&v)) return static_cast<int64_t>(*d);
  if (auto* t = std::get_if<std::string>(&v)) return std::strtoll(t->c_str(), nullptr, 10);
  return 0;
}

double SqlRow::Double(int col) const {
  const SqlValue& v = cells_.at(col);
  if (auto* d = std::get_if<double>(&v)) return *d;
  if (auto* i = std::get_if<int64_t>(&v)) return static_cast<double>(*i);
  if (auto* t = std::get_if<std::string>(&v)) return std::strtod(t->c_str(), nullptr);
  return 0;
}

std::string SqlRow::Text(int col) const {
  const SqlValue& v = cells_.at(col);
  if (auto* t = std::get_if<std::string>(&v)) return *t;
  if (auto* i = std::get_if<int64_t>(&v)) return std::to_string(*i);
  if (auto* d = std::get_if<double>(&v)) return absl::StrFormat("%.17g", *d);
  if (auto* b = std::get_if<std::vector<uint8_t>>(&v)) return std::string(b->begin(), b->end());
  return std::string();
}

std::vector<uint8_t> SqlRow::Blob(int col) const {
  const SqlValue& v = cells_.at(col);
  if (auto* b = std::get_if<std::vector<uint8_t>>(&v)) return *b;
  if (auto* t = std::get_if<std::string>(&v)) return std::vector<uint8_t>(t->begin(), t->end());
  return {};
}

absl::Status SqlSource::InsertRows(std::string_view table, const std::vector<std::string>& columns,
                                   const std::vector<std::vector<SqlValue>>& rows) {
  std::vector<std::string> marks(columns.size(), "?");
  const std::string sql = absl::StrCat("INSERT INTO ", std::string(table), " (", absl::StrJoin(columns, ", "), ") VALUES (",
                                       absl::StrJoin(marks, ","), ")");
  for (const auto& row : rows) {
    if (auto st = Exec(sql, row); !st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::StatusOr<SqlRow> SqlSource::QueryOne(std::string_view sql, const std::vector<SqlValue>& params,
                                           const std::string& not_found) {
  auto rows = Query(sql, params);
  if (!rows.ok()) return rows.status();
  if (rows->empty()) return absl::NotFoundError(not_found);
  return std::move(rows->front());
}

absl::Status SqlSource::Exec(std::string_view sql, const std::vector<SqlValue>& params) {
  return Query(sql, params).status();
}

absl::Status SqlPool::BackupTo(const std::string&) {
  return absl::UnimplementedError("online backup is a SQLite feature; back PostgreSQL up with pg_dump");
}

}  // namespace fluxcal::storage
