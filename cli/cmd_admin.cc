// fluxcal admin migrate --from sqlite:PATH --to postgresql://... [--json]
// fluxcal admin backup --db PATH --out FILE [--json]
// fluxcal admin hash --db URL [--json]
// Store administration: move a plant's store from SQLite to PostgreSQL
// (verified by content hashes over everything stored), an online backup of
// a SQLite store while it serves (sqlite3 backup API), and the content hash
// itself. PostgreSQL is backed up with pg_dump (docs/service.md).
#include <cstdio>
#include <filesystem>
#include <system_error>

#include "absl/strings/match.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_store.h"
#include "nlohmann/json.hpp"
#include "pipeline/pipeline.h"
#include "pipeline/store.h"

namespace fluxcal::cli {
namespace {

int Fail(const std::string& m, int code = 1) { return CommandError("admin", m, code); }

void Print(const nlohmann::json& j, bool json, const std::string& text) {
  if (json) {
    PrintJson(j);
  } else {
    std::printf("%s\n", text.c_str());
  }
}

int Migrate(const ParsedArgs& a) {
  const auto from = a.Get("from"), to = a.Get("to");
  if (!from || !to) return Fail("usage: fluxcal admin migrate --from sqlite:PATH --to postgresql://... [--json]", 2);
  const std::string src_path = absl::StartsWith(*from, "sqlite:") ? from->substr(7) : *from;
  if (absl::StartsWith(*from, "postgres") || !std::filesystem::exists(src_path)) {
    return Fail("--from: expected an existing SQLite store (sqlite:PATH), got '" + *from + "'");
  }
  auto src = pipeline::OpenStore(*from, /*create=*/false);
  if (!src.ok()) return Fail(std::string(src.status().message()));
  auto dst = pipeline::OpenStore(*to);
  if (!dst.ok()) return Fail(std::string(dst.status().message()));
  std::fprintf(stderr, "admin: migrating %s -> %s\n", (*src)->Backend().c_str(), (*dst)->Backend().c_str());
  auto r = pipeline::Migrate(**src, **dst);
  if (!r.ok()) return Fail(std::string(r.status().message()));
  Print({{"motors", r->motors}, {"runs", r->runs}, {"points", r->points}, {"recordings", r->recordings},
         {"calibrations", r->calibrations}, {"releases", r->releases}, {"audit_rows", r->audit_rows},
         {"chain_links", r->chain_links}, {"release_links", r->release_links},
         {"content_sha256", r->content_sha256}, {"verified", true}},
        a.Has("json"),
        "migrated " + std::to_string(r->motors) + " motors, " + std::to_string(r->runs) + " runs, " +
            std::to_string(r->points) + " points, " + std::to_string(r->recordings) + " recordings, " +
            std::to_string(r->calibrations) + " calibrations, " + std::to_string(r->releases) + " releases, " +
            std::to_string(r->audit_rows) + " audit rows, " + std::to_string(r->chain_links) + " chain links, " +
            std::to_string(r->release_links) + " release links; content sha256 " + r->content_sha256 +
            " equal on both sides");
  return 0;
}

int Backup(const ParsedArgs& a) {
  const auto db = a.Get("db"), out = a.Get("out");
  if (!db || !out) return Fail("usage: fluxcal admin backup --db PATH --out FILE [--force] [--json]", 2);
  if (absl::StartsWith(*db, "postgres")) {
    return Fail("--db: PostgreSQL is backed up with pg_dump -Fc (docs/service.md), not with fluxcal", 2);
  }
  // The overwrite rule (cli/args.h); SQLite's -wal and -shm beside an old
  // backup count too: a new file under the old name would replay them.
  if (auto e = CheckOverwrite(a, {{"out", *out}, {"out", *out + "-wal"}, {"out", *out + "-shm"}}); !e.empty()) {
    return Fail(e);
  }
  const std::string path = absl::StartsWith(*db, "sqlite:") ? db->substr(7) : *db;
  if (!std::filesystem::exists(path)) return Fail("--db: no SQLite store at '" + path + "'");
  for (const std::string& old : {*out, *out + "-wal", *out + "-shm"}) {   // --force given, or none exists
    std::error_code ec;
    std::filesystem::remove(old, ec);
  }
  auto store = pipeline::BackupSqliteStore(path, *out);
  if (!store.ok()) return Fail(std::string(store.status().message()));
  auto copy = pipeline::OpenStore(*out);
  if (!copy.ok()) return Fail(std::string(copy.status().message()));
  auto h1 = pipeline::ContentHash(**store);
  auto h2 = pipeline::ContentHash(**copy);
  if (!h1.ok() || !h2.ok()) return Fail("content hash failed");
  // A server may have committed between the backup and the hash of the
  // live store: report both; the backup's own hash is its identity.
  Print({{"out", *out}, {"content_sha256", *h2}, {"live_content_sha256", *h1}, {"equal", *h1 == *h2}}, a.Has("json"),
        *out + ": backup content sha256 " + *h2 + (*h1 == *h2 ? " (equal to the live store)" : " (live store moved on)"));
  return 0;
}

int Hash(const ParsedArgs& a) {
  const auto db = a.Get("db");
  if (!db) return Fail("usage: fluxcal admin hash --db URL [--json]", 2);
  // Only reads: a store that does not exist is refused, not created.
  auto store = OpenExistingStore("admin", a);
  if (!store) return 1;
  auto h = pipeline::ContentHash(*store);
  if (!h.ok()) return Fail(std::string(h.status().message()));
  Print({{"backend", store->Backend()}, {"content_sha256", *h}}, a.Has("json"), *h);
  return 0;
}

const FlagSpecs kAdminFlags = {
    {"from", "URL", "migrate: source store, sqlite:PATH"},
    {"to", "URL", "migrate: target store, postgresql://USER@HOST:PORT/DB"},
    {"db", "URL", "backup, hash: the store (SQLite PATH; hash also postgresql://...)"},
    {"out", "FILE", "backup: the SQLite backup file to write"},
    kJsonFlag,
    {kForceFlag.name, kForceFlag.value, "backup: " + kForceFlag.help},
};

int RunAdmin(const std::vector<std::string>& argv) {
  if (argv.empty()) {
    return Fail("usage: fluxcal admin migrate|backup|hash|anchor|verify-db|add-key|add-cert|revoke|list-keys|keygen ...",
                2);
  }
  auto a = ParseArgs(std::vector<std::string>(argv.begin() + 1, argv.end()), kAdminFlags);
  if (!a.ok()) return Fail(std::string(a.status().message()), 2);
  if (!a->positional.empty()) return Fail("unexpected argument '" + a->positional[0] + "'", 2);
  if (argv[0] == "migrate") return Migrate(*a);
  if (argv[0] == "backup") return Backup(*a);
  if (argv[0] == "hash") return Hash(*a);
  return Fail("unknown admin command '" + argv[0] +
                  "' (migrate, backup, hash, anchor, verify-db, add-key, add-cert, revoke, list-keys, keygen)",
              2);
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("admin", "store administration: migrate SQLite to PostgreSQL, backup, content hash",
                         RunAdmin,
                         "fluxcal admin migrate --from sqlite:PATH --to postgresql://... [--json]\n"
                         "fluxcal admin backup --db PATH --out FILE [--force] [--json]\n"
                         "fluxcal admin hash --db URL [--json]\n"
                         "fluxcal admin keygen|add-key|add-cert|revoke|list-keys|verify-db|anchor ...  (fluxcal help admin add-key, ...)",
                         kAdminFlags);

}  // namespace fluxcal::cli
