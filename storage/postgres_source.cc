#include "storage/postgres_source.h"

#include <libpq-fe.h>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "storage/dialect.h"

namespace fluxcal::storage {
namespace {

// Type oids (catalog/pg_type.h, stable across versions) for the parameters
// and the result columns the store uses.
constexpr Oid kBool = 16, kBytea = 17, kInt8 = 20, kInt2 = 21, kInt4 = 23, kText = 25, kFloat4 = 700,
              kFloat8 = 701;

struct ResultDeleter {
  void operator()(PGresult* r) const { PQclear(r); }
};
using Result = std::unique_ptr<PGresult, ResultDeleter>;

absl::Status PgError(PGconn* c, const PGresult* r, std::string_view what) {
  const char* state = r ? PQresultErrorField(r, PG_DIAG_SQLSTATE) : nullptr;
  std::string detail = r ? PQresultErrorMessage(r) : PQerrorMessage(c);
  while (!detail.empty() && (detail.back() == '\n' || detail.back() == ' ')) detail.pop_back();
  const std::string msg = absl::StrCat("postgresql: ", std::string(what), ": ", detail);
  const std::string code = state ? state : "";
  if (PQstatus(c) != CONNECTION_OK || absl::StartsWith(code, "08") || absl::StartsWith(code, "57P")) {
    return absl::UnavailableError(msg);
  }
  if (absl::StartsWith(code, "23")) return absl::AlreadyExistsError(msg);
  if (code == "40001" || code == "40P01") return absl::AbortedError(msg);
  if (code == "P0001") return absl::FailedPreconditionError(msg);
  return absl::InternalError(msg);
}

std::string Shorten(std::string_view sql) {
  std::string what(sql);
  if (what.size() > 80) what = what.substr(0, 80) + "...";
  return what;
}

// The shared SQL's `?` as $1, $2, ... (outside quoted literals).
std::string Numbered(std::string_view sql) {
  std::string out;
  out.reserve(sql.size() + 16);
  bool quoted = false;
  int n = 0;
  for (char ch : sql) {
    if (ch == '\'') quoted = !quoted;
    if (ch == '?' && !quoted) {
      absl::StrAppend(&out, "$", ++n);
    } else {
      out.push_back(ch);
    }
  }
  return out;
}

// A result cell as the store reads it: numbers as numbers, bytea as bytes.
SqlValue Cell(const PGresult* r, int row, int col) {
  if (PQgetisnull(r, row, col)) return nullptr;
  const char* v = PQgetvalue(r, row, col);
  switch (PQftype(r, col)) {
    case kInt2: case kInt4: case kInt8: return static_cast<int64_t>(std::strtoll(v, nullptr, 10));
    case kFloat4: case kFloat8: return std::strtod(v, nullptr);
    case kBool: return int64_t{v[0] == 't' ? 1 : 0};
    case kBytea: {
      size_t n = 0;
      unsigned char* b = PQunescapeBytea(reinterpret_cast<const unsigned char*>(v), &n);
      std::vector<uint8_t> out(b, b + (b ? n : 0));
      PQfreemem(b);
      return out;
    }
    default: return std::string(v, PQgetlength(r, row, col));
  }
}

// COPY text format: backslash, tab, newline and carriage return escaped.
void AppendCopyText(std::string* out, const SqlValue& v) {
  if (std::holds_alternative<std::nullptr_t>(v)) {
    out->append("\\N");
    return;
  }
  if (auto* i = std::get_if<int64_t>(&v)) {
    absl::StrAppend(out, *i);
    return;
  }
  // 17 significant digits: every double round-trips exactly.
  if (auto* d = std::get_if<double>(&v)) {
    absl::StrAppendFormat(out, "%.17g", *d);
    return;
  }
  if (auto* b = std::get_if<std::vector<uint8_t>>(&v)) {
    out->append("\\\\x");
    for (uint8_t byte : *b) absl::StrAppendFormat(out, "%02x", byte);
    return;
  }
  for (char ch : std::get<std::string>(v)) {
    switch (ch) {
      case '\\': out->append("\\\\"); break;
      case '\t': out->append("\\t"); break;
      case '\n': out->append("\\n"); break;
      case '\r': out->append("\\r"); break;
      default: out->push_back(ch);
    }
  }
}

class PostgresSource final : public SqlSource {
 public:
  explicit PostgresSource(PGconn* c) : c_(c) {}
  const Dialect& dialect() const override { return PostgresDialect(); }
  PGconn* conn() const { return c_; }

  absl::StatusOr<SqlRows> Query(std::string_view sql, const std::vector<SqlValue>& params) override {
    const std::string text = Numbered(sql);
    // Each parameter typed by its value: numbers compare and insert as
    // numbers, bytes travel as binary bytea, NULL takes the column's type.
    std::vector<std::string> storage(params.size());
    std::vector<const char*> values(params.size());
    std::vector<int> lengths(params.size()), formats(params.size());
    std::vector<Oid> types(params.size());
    for (size_t k = 0; k < params.size(); ++k) {
      const SqlValue& p = params[k];
      if (std::holds_alternative<std::nullptr_t>(p)) continue;   // values[k] nullptr: NULL, type inferred
      if (auto* i = std::get_if<int64_t>(&p)) storage[k] = std::to_string(*i), types[k] = kInt8;
      else if (auto* d = std::get_if<double>(&p)) storage[k] = absl::StrFormat("%.17g", *d), types[k] = kFloat8;
      else if (auto* t = std::get_if<std::string>(&p)) storage[k] = *t, types[k] = kText;
      else if (auto* b = std::get_if<std::vector<uint8_t>>(&p)) {
        storage[k].assign(b->begin(), b->end());
        types[k] = kBytea;
        formats[k] = 1;
      }
      values[k] = storage[k].data();
      lengths[k] = static_cast<int>(storage[k].size());
    }
    Result r(PQexecParams(c_, text.c_str(), static_cast<int>(params.size()), types.data(), values.data(),
                          lengths.data(), formats.data(), 0));
    const auto st = r ? PQresultStatus(r.get()) : PGRES_FATAL_ERROR;
    if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) return PgError(c_, r.get(), Shorten(sql));
    SqlRows rows;
    rows.reserve(PQntuples(r.get()));
    for (int i = 0; i < PQntuples(r.get()); ++i) {
      std::vector<SqlValue> cells(PQnfields(r.get()));
      for (int c = 0; c < PQnfields(r.get()); ++c) cells[c] = Cell(r.get(), i, c);
      rows.emplace_back(std::move(cells));
    }
    return rows;
  }

  absl::Status ExecScript(std::string_view sql) override {
    const std::string text(sql);
    Result r(PQexec(c_, text.c_str()));
    const auto st = r ? PQresultStatus(r.get()) : PGRES_FATAL_ERROR;
    if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) return PgError(c_, r.get(), Shorten(sql));
    return absl::OkStatus();
  }
  absl::Status Begin() override { return ExecScript(dialect().begin); }
  absl::Status Commit() override { return ExecScript("COMMIT"); }
  absl::Status Rollback() override { return ExecScript("ROLLBACK"); }

  // All rows in one COPY: one round trip for any number of points.
  absl::Status InsertRows(std::string_view table, const std::vector<std::string>& columns,
                          const std::vector<std::vector<SqlValue>>& rows) override {
    if (rows.empty()) return absl::OkStatus();
    const std::string what = absl::StrCat("COPY ", std::string(table));
    const std::string sql = absl::StrCat(what, " (", absl::StrJoin(columns, ", "), ") FROM STDIN");
    Result r(PQexec(c_, sql.c_str()));
    if (!r || PQresultStatus(r.get()) != PGRES_COPY_IN) return PgError(c_, r.get(), what);
    std::string buf;
    buf.reserve(rows.size() * 200);
    for (const auto& row : rows) {
      for (size_t k = 0; k < row.size(); ++k) {
        if (k > 0) buf.push_back('\t');
        AppendCopyText(&buf, row[k]);
      }
      buf.push_back('\n');
    }
    if (PQputCopyData(c_, buf.data(), static_cast<int>(buf.size())) != 1 || PQputCopyEnd(c_, nullptr) != 1) {
      return PgError(c_, nullptr, what + " data");
    }
    absl::Status st;
    while (PGresult* res = PQgetResult(c_)) {
      Result rr(res);
      if (PQresultStatus(res) != PGRES_COMMAND_OK && st.ok()) st = PgError(c_, res, what);
    }
    return st;
  }

 private:
  PGconn* c_;
};

class PostgresPool final : public SqlPool {
 public:
  PostgresPool(std::string url, int max) : url_(std::move(url)), max_(max) {}
  ~PostgresPool() override {
    for (PGconn* c : idle_) PQfinish(c);
  }
  const Dialect& dialect() const override { return PostgresDialect(); }

  absl::Status WithSource(const std::function<absl::Status(SqlSource&)>& fn) override {
    auto c = Acquire();
    if (!c.ok()) return c.status();
    PostgresSource source(*c);
    absl::Status st = fn(source);
    Release(*c);
    return st;
  }

 private:
  absl::StatusOr<PGconn*> Acquire() {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return !idle_.empty() || open_ < max_; });
    if (!idle_.empty()) {
      PGconn* c = idle_.back();
      idle_.pop_back();
      return c;
    }
    ++open_;
    lock.unlock();
    PGconn* c = PQconnectdb(url_.c_str());
    if (PQstatus(c) != CONNECTION_OK) {
      const std::string msg = PQerrorMessage(c);
      PQfinish(c);
      std::lock_guard<std::mutex> relock(mu_);
      --open_;
      cv_.notify_one();
      return absl::UnavailableError(absl::StrCat("postgresql: cannot connect: ", msg));
    }
    // Quiet notices (e.g. "relation already exists, skipping").
    PQsetNoticeProcessor(c, [](void*, const char*) {}, nullptr);
    return c;
  }

  void Release(PGconn* c) {
    std::lock_guard<std::mutex> lock(mu_);
    if (PQstatus(c) != CONNECTION_OK || PQtransactionStatus(c) != PQTRANS_IDLE) {
      PQfinish(c);   // broken or left inside a transaction: never reuse
      --open_;
    } else {
      idle_.push_back(c);
    }
    cv_.notify_one();
  }

  std::string url_;
  int max_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<PGconn*> idle_;
  int open_ = 0;
};

}  // namespace

absl::StatusOr<std::unique_ptr<SqlPool>> OpenPostgresPool(const std::string& url_in, int max_connections) {
  // A database that does not answer must fail a call, not hang it: bound
  // the connect unless the URI says otherwise.
  std::string url = url_in;
  if (url.find("connect_timeout") == std::string::npos) {
    url += url.find('?') == std::string::npos ? "?connect_timeout=5" : "&connect_timeout=5";
  }
  return std::unique_ptr<SqlPool>(new PostgresPool(url, std::max(1, max_connections)));
}

}  // namespace fluxcal::storage
