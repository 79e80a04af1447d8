// A throw-away PostgreSQL server for tests and benchmarks: initdb into a
// temporary directory, pg_ctl start on a free loopback port (and a socket
// in that directory), stopped and deleted on destruction. Uses Debian's
// /usr/lib/postgresql/<version>/bin; as root the server runs as the
// `postgres` user (PostgreSQL refuses to run as root). In a build without
// libpq (FLUXCAL_WITH_POSTGRESQL unset) no cluster starts and every test
// that needs one skips, saying why.
#ifndef FLUXCAL_TESTS_SUPPORT_PG_CLUSTER_H_
#define FLUXCAL_TESTS_SUPPORT_PG_CLUSTER_H_

#ifdef FLUXCAL_WITH_POSTGRESQL
#include <libpq-fe.h>
#endif
#include <netinet/in.h>
#include <pwd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

namespace fluxcal::testing {

class PgCluster {
 public:
  // nullptr (and *why) when PostgreSQL is not installed here. `durable`
  // false turns fsync off (tests that do not crash the database).
  static std::unique_ptr<PgCluster> Start(std::string* why, bool durable = false) {
    namespace fs = std::filesystem;
#ifndef FLUXCAL_WITH_POSTGRESQL
    *why = "PostgreSQL is not built into this fluxcal (libpq was not found at configure)";
    (void)durable;
    return nullptr;
#endif
    std::string bin;
    if (const char* env = std::getenv("FLUXCAL_PG_BIN")) bin = env;
    if (bin.empty() && fs::exists("/usr/lib/postgresql")) {
      for (const auto& e : fs::directory_iterator("/usr/lib/postgresql")) {
        if (fs::exists(e.path() / "bin" / "initdb") && e.path().string() > bin) bin = (e.path() / "bin").string();
      }
    }
    if (bin.empty() || !fs::exists(bin + "/initdb") || !fs::exists(bin + "/pg_ctl")) {
      *why = "PostgreSQL is not installed (no /usr/lib/postgresql/<version>/bin/initdb; "
             "scripts/install-deps.sh installs it)";
      return nullptr;
    }
    std::unique_ptr<PgCluster> c(new PgCluster);
    c->bin_ = bin;
    char tmpl[] = "/tmp/fluxcal-pg-XXXXXX";
    if (!mkdtemp(tmpl)) { *why = "mkdtemp failed"; return nullptr; }
    c->dir_ = tmpl;
    if (getuid() == 0) {
      const passwd* pw = getpwnam("postgres");
      if (!pw) {
        *why = "running as root and there is no 'postgres' user to run PostgreSQL as";
        return nullptr;
      }
      if (chown(c->dir_.c_str(), pw->pw_uid, pw->pw_gid) != 0) { *why = "chown failed"; return nullptr; }
      c->as_ = "runuser -u postgres -- ";
    }
    const std::string data = c->dir_ + "/data";
    if (c->Run("'" + bin + "/initdb' -D '" + data + "' -U fluxcal -A trust -E UTF8 --no-sync > '" + c->dir_ +
               "/initdb.log' 2>&1") != 0) {
      *why = "initdb failed (see " + c->dir_ + "/initdb.log)";
      c->keep_ = true;
      return nullptr;
    }
    for (int attempt = 0; attempt < 3; ++attempt) {
      c->port_ = FreePort();
      std::string opts = "-c listen_addresses=127.0.0.1 -p " + std::to_string(c->port_) +
                         " -c unix_socket_directories=" + c->dir_ + " -c max_connections=300";
      if (!durable) opts += " -c fsync=off -c synchronous_commit=off -c full_page_writes=off";
      if (c->Run("'" + bin + "/pg_ctl' -D '" + data + "' -l '" + c->dir_ + "/server.log' -w -t 60 -o '" + opts +
                 "' start > /dev/null 2>&1") == 0) {
        c->running_ = true;
        return c;
      }
    }
    *why = "pg_ctl start failed (see " + c->dir_ + "/server.log)";
    c->keep_ = true;
    return nullptr;
  }

  ~PgCluster() {
    if (running_) Run("'" + bin_ + "/pg_ctl' -D '" + dir_ + "/data' -m immediate -w stop > /dev/null 2>&1");
    std::error_code ec;
    if (!keep_) std::filesystem::remove_all(dir_, ec);
  }

  int port() const { return port_; }
  std::string Url(const std::string& database) const {
    return "postgresql://fluxcal@127.0.0.1:" + std::to_string(port_) + "/" + database;
  }
  // CREATE DATABASE name; false on failure.
  bool CreateDatabase(const std::string& name) const { return Sql("postgres", "CREATE DATABASE " + name); }
  // Runs one statement; true when it succeeded.
  bool Sql(const std::string& database, const std::string& sql) const {
#ifndef FLUXCAL_WITH_POSTGRESQL
    (void)database, (void)sql;
    return false;
#else
    PGconn* c = PQconnectdb(Url(database).c_str());
    bool ok = PQstatus(c) == CONNECTION_OK;
    if (ok) {
      PGresult* r = PQexec(c, sql.c_str());
      ok = PQresultStatus(r) == PGRES_COMMAND_OK || PQresultStatus(r) == PGRES_TUPLES_OK;
      PQclear(r);
    }
    PQfinish(c);
    return ok;
#endif
  }
  // First column of the first row, "" on error.
  std::string Scalar(const std::string& database, const std::string& sql) const {
#ifndef FLUXCAL_WITH_POSTGRESQL
    (void)database, (void)sql;
    return "";
#else
    PGconn* c = PQconnectdb(Url(database).c_str());
    std::string out;
    if (PQstatus(c) == CONNECTION_OK) {
      PGresult* r = PQexec(c, sql.c_str());
      if (PQresultStatus(r) == PGRES_TUPLES_OK && PQntuples(r) > 0) out = PQgetvalue(r, 0, 0);
      PQclear(r);
    }
    PQfinish(c);
    return out;
#endif
  }

 private:
  PgCluster() = default;
  int Run(const std::string& cmd) const { return std::system((as_ + "sh -c \"" + Escape(cmd) + "\"").c_str()); }
  static std::string Escape(const std::string& s) {
    std::string o;
    for (char ch : s) {
      if (ch == '"' || ch == '\\' || ch == '$' || ch == '`') o.push_back('\\');
      o.push_back(ch);
    }
    return o;
  }

 public:
  // A port on 127.0.0.1 that was free a moment ago.
  static int FreePort() {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    socklen_t len = sizeof a;
    int port = 0;
    if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
        getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
      port = ntohs(a.sin_port);
    }
    close(fd);
    return port;
  }

 private:

  std::string bin_, dir_, as_;
  int port_ = 0;
  bool running_ = false, keep_ = false;
};

// Tests skip only when PostgreSQL is not installed or not built in; a
// cluster that is installed but does not start is a failure.
#define FLUXCAL_PG_OR_SKIP(pg, why, what)                                        \
  if (!(pg)) {                                                                  \
    if ((why).rfind("PostgreSQL is not installed", 0) == 0 || (why).rfind("PostgreSQL is not built", 0) == 0) \
      GTEST_SKIP() << what << ": " << (why);                                    \
    FAIL() << what << ": " << (why);                                            \
  }

// One cluster per test program, started on first use.
inline PgCluster* SharedPgCluster(std::string* why) {
  static std::string reason;
  static std::unique_ptr<PgCluster> cluster = PgCluster::Start(&reason);
  *why = reason;
  return cluster.get();
}

}  // namespace fluxcal::testing

#endif  // FLUXCAL_TESTS_SUPPORT_PG_CLUSTER_H_
