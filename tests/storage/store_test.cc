// Store conformance: one suite, run on SQLite (":memory:" and a file) and on
// a real PostgreSQL server started in a temporary directory: migrations,
// all-or-nothing runs, exact round trips, immutable calibration versions
// (refused by the database itself), gap-free versions under concurrent
// writers on separate connections, listing, history, whole-store access;
// the hash chains over calibrations and releases, tampering behind the
// store found by them and by an anchor, and stores that must exist.
#include "storage/store.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <functional>
#include <set>
#include <thread>

#include "gtest/gtest.h"
#include "storage/dialect.h"
#include "storage/sql_source.h"
#include "storage/sqlite.h"
#include "storage/sqlite_source.h"
#ifdef FLUXCAL_WITH_POSTGRESQL
#include "storage/postgres_source.h"
#endif
#include "tests/support/old_schema.h"
#include "tests/support/pg_cluster.h"

namespace fluxcal::storage {
namespace {

namespace fs = std::filesystem;

enum class Backend { kSqliteMemory, kSqliteFile, kPostgres };

std::string Name(const ::testing::TestParamInfo<Backend>& i) {
  switch (i.param) {
    case Backend::kSqliteMemory: return "SqliteMemory";
    case Backend::kSqliteFile: return "SqliteFile";
    default: return "PostgreSQL";
  }
}

class StoreTest : public ::testing::TestWithParam<Backend> {
 protected:
  void SetUp() override {
    static std::atomic<int> counter{0};
    const int n = counter++;
    switch (GetParam()) {
      case Backend::kSqliteMemory:
        url_ = ":memory:";
        break;
      case Backend::kSqliteFile:
        path_ = (fs::temp_directory_path() / ("fluxcal_store_" + std::to_string(::getpid()) + "_" + std::to_string(n) + ".db")).string();
        fs::remove(path_);
        url_ = "sqlite:" + path_;
        break;
      case Backend::kPostgres: {
        std::string why;
        pg_ = fluxcal::testing::SharedPgCluster(&why);
        FLUXCAL_PG_OR_SKIP(pg_, why, "PostgreSQL conformance run skipped");
        db_ = "conf_" + std::to_string(n);
        ASSERT_TRUE(pg_->CreateDatabase(db_));
        url_ = pg_->Url(db_);
        break;
      }
    }
    auto s = Store::Open(url_);
    ASSERT_TRUE(s.ok()) << s.status();
    store_ = std::move(*s);
  }
  void TearDown() override {
    store_.reset();
    if (!path_.empty()) {
      for (auto sfx : {"", "-wal", "-shm"}) fs::remove(path_ + sfx);
    }
  }
  // Runs raw SQL against the backend, bypassing the Store.
  bool RawSql(const std::string& sql) {
    if (GetParam() == Backend::kPostgres) return pg_->Sql(db_, sql);
    auto db = Database::Open(path_);
    return db.ok() && (*db)->Exec(sql).ok();
  }
  std::vector<HfPointRow> Points(int n) {
    std::vector<HfPointRow> v;
    for (int k = 0; k < n; ++k) {
      HfPointRow p;
      p.point_id = "p" + std::to_string(k);
      p.id_a = -20.0 * k; p.iq_a = 40; p.ld_h = 1.8e-4 + k * 1e-19 + 1.0 / 3.0 * 1e-7; p.lq_h = 3.6e-4;
      p.ld_h_std = 1e-7; p.lq_h_std = 1e-7;
      if (k % 2) p.ldq_h = -1.234567890123456789e-6;
      if (k % 3 == 1) p.hf_flux_radius_wb = 1.0 / 3.0 * 4.7e-3;
      p.reliable = k % 3 != 0;
      v.push_back(p);
    }
    return v;
  }
  bool SeparateConnections() const { return GetParam() != Backend::kSqliteMemory; }

  fluxcal::testing::PgCluster* pg_ = nullptr;
  std::string url_, path_, db_;
  std::unique_ptr<Store> store_;
};

TEST_P(StoreTest, MigratesToCurrentSchema) {
  auto v = store_->SchemaVersion();
  ASSERT_TRUE(v.ok()) << v.status();
  EXPECT_EQ(*v, kSchemaVersion);
  EXPECT_EQ(store_->Backend(), GetParam() == Backend::kPostgres ? "postgresql" : "sqlite");
  if (SeparateConnections()) {
    store_.reset();
    auto again = Store::Open(url_);   // idempotent re-open
    ASSERT_TRUE(again.ok()) << again.status();
    EXPECT_EQ(*(*again)->SchemaVersion(), kSchemaVersion);
    store_ = std::move(*again);
  }
}

TEST_P(StoreTest, RunAndPointsRoundTripExactly) {
  const auto in = Points(36);
  auto run = store_->IngestHfRun({"IPM-1", 4, 0.011, 0.0114, ""}, "st1", "hf_run", in);
  ASSERT_TRUE(run.ok()) << run.status();
  int64_t id = 0;
  auto pts = store_->LatestRunPoints("IPM-1", &id);
  ASSERT_TRUE(pts.ok());
  EXPECT_EQ(id, *run);
  ASSERT_EQ(pts->size(), 36u);
  for (size_t k = 0; k < in.size(); ++k) {
    EXPECT_EQ((*pts)[k].point_id, in[k].point_id);
    EXPECT_EQ((*pts)[k].ld_h, in[k].ld_h) << "doubles must round-trip bit-exactly";
    EXPECT_EQ((*pts)[k].ldq_h, in[k].ldq_h);
    EXPECT_EQ((*pts)[k].hf_flux_radius_wb, in[k].hf_flux_radius_wb) << "absent stays absent, bit-exact otherwise";
    EXPECT_EQ((*pts)[k].reliable, in[k].reliable);
  }
  EXPECT_TRUE((*pts)[4].hf_flux_radius_wb.has_value());
  EXPECT_FALSE((*pts)[5].hf_flux_radius_wb.has_value());
  EXPECT_DOUBLE_EQ((*pts)[5].id_a, -100.0);
  EXPECT_FALSE((*pts)[4].ldq_h.has_value());
  auto m = store_->GetMotor("IPM-1");
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->rs_ohm, 0.011);
  EXPECT_EQ(m->created_utc.size(), 20u);
  EXPECT_EQ(store_->LatestRunPoints("NOPE", &id).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store_->GetMotor("NOPE").status().code(), absl::StatusCode::kNotFound);
}

TEST_P(StoreTest, RecordingsAreContentAddressed) {
  std::vector<uint8_t> blob = {0, 1, 2, 0, 255, '\\', '\n', 0};
  for (int k = 0; k < 5000; ++k) blob.push_back(static_cast<uint8_t>(k * 7));
  ASSERT_TRUE(store_->IngestHfRun({"IPM-R", 4, 0.01, 0.01, ""}, "st", "recording", Points(2), "abc", blob, 12345).ok());
  ASSERT_TRUE(store_->IngestHfRun({"IPM-R", 4, 0.01, 0.01, ""}, "st", "recording", Points(2), "abc", blob, 12345).ok());
  EXPECT_EQ(*store_->LatestRecordingSha("IPM-R"), "abc");
  EXPECT_EQ(*store_->GetRecording("abc"), blob);
  auto row = store_->GetRecordingRow("abc");
  ASSERT_TRUE(row.ok());
  EXPECT_EQ(row->size_bytes, 12345);
  EXPECT_EQ(store_->GetRecording("nope").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store_->LatestRecordingSha("IPM-1").status().code(), absl::StatusCode::kNotFound);
}

TEST_P(StoreTest, CalibrationVersionsAreImmutable) {
  ASSERT_TRUE(store_->IngestHfRun({"IPM-2", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3)).ok());
  CalibrationRow c;
  c.serial = "IPM-2"; c.model = "analytic"; c.verdict = "pass"; c.calibration_json = "{}";
  EXPECT_EQ(*store_->AddCalibration(c), 1);
  c.verdict = "fail: x";
  EXPECT_EQ(*store_->AddCalibration(c), 2);
  EXPECT_EQ(store_->GetCalibration("IPM-2", 1)->verdict, "pass");
  EXPECT_EQ(store_->GetCalibration("IPM-2", 0)->version, 2);
  if (SeparateConnections()) {
    // The database itself refuses to change a stored version.
    EXPECT_FALSE(RawSql("UPDATE calibrations SET verdict = 'pass' WHERE version = 2"));
    EXPECT_FALSE(RawSql("DELETE FROM calibrations"));
    EXPECT_TRUE(RawSql("SELECT 1 FROM calibrations")) << "raw access works, so the refusals above are real";
    EXPECT_EQ(store_->GetCalibration("IPM-2", 2)->verdict, "fail: x");
  }
  EXPECT_EQ(store_->GetCalibration("IPM-2", 3).status().code(), absl::StatusCode::kNotFound);
  c.serial = "IPM-UNKNOWN";
  EXPECT_FALSE(store_->AddCalibration(c).ok());
}

// Releases: only a passing version, once, immutable; the audit trail is
// append-only; idempotency keys return the first run.
TEST_P(StoreTest, ReleasesAuditAndIdempotency) {
  bool replayed = true;
  auto r1 = store_->IngestHfRun({"IPM-R", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3), "", {}, 0, "k1", &replayed);
  ASSERT_TRUE(r1.ok()) << r1.status();
  EXPECT_FALSE(replayed);
  auto r2 = store_->IngestHfRun({"IPM-R", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(5), "", {}, 0, "k1", &replayed);
  ASSERT_TRUE(r2.ok());
  EXPECT_TRUE(replayed);
  EXPECT_EQ(*r2, *r1);
  int64_t latest = 0;
  EXPECT_EQ(store_->LatestRunPoints("IPM-R", &latest)->size(), 3u);   // the retry stored nothing
  CalibrationRow c;
  c.serial = "IPM-R"; c.model = "analytic"; c.verdict = "pass"; c.calibration_json = "{}";
  ASSERT_EQ(*store_->AddCalibration(c), 1);
  c.verdict = "fail: residual";
  ASSERT_EQ(*store_->AddCalibration(c), 2);
  EXPECT_EQ(*store_->LatestReleasedVersion("IPM-R"), 0);
  EXPECT_EQ(store_->Release("IPM-R", 2, "rel").code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->Release("IPM-R", 7, "rel").code(), absl::StatusCode::kNotFound);
  ASSERT_TRUE(store_->Release("IPM-R", 1, "rel").ok());
  EXPECT_EQ(store_->Release("IPM-R", 1, "rel").code(), absl::StatusCode::kAlreadyExists);
  EXPECT_EQ(*store_->LatestReleasedVersion("IPM-R"), 1);
  EXPECT_TRUE(*store_->IsReleased("IPM-R", 1));
  EXPECT_FALSE(*store_->IsReleased("IPM-R", 2));
  AuditRow a;
  a.identity = "station-7"; a.role = "station"; a.peer = "ipv4:127.0.0.1:1"; a.request_id = "r1";
  a.rpc = "Fit"; a.serial = "IPM-R"; a.detail = "version 1";
  ASSERT_TRUE(store_->AppendAudit(a).ok());
  a.rpc = "Release";
  ASSERT_TRUE(store_->AppendAudit(a).ok());
  auto rows = store_->AuditOf("IPM-R");
  ASSERT_TRUE(rows.ok());
  ASSERT_EQ(rows->size(), 2u);
  EXPECT_EQ((*rows)[0].rpc, "Fit");
  EXPECT_EQ((*rows)[1].rpc, "Release");
  EXPECT_FALSE((*rows)[0].utc.empty());
  if (SeparateConnections()) {
    EXPECT_FALSE(RawSql("UPDATE audit SET identity = 'someone'"));
    EXPECT_FALSE(RawSql("DELETE FROM audit"));
    EXPECT_FALSE(RawSql("DELETE FROM releases"));
    EXPECT_TRUE(RawSql("SELECT 1 FROM audit"));
  }
}

// Each audited write inserts its audit row in its own transaction: both
// appear together, a refused write leaves no row, and a refused audit
// insert (a trigger added behind the store's back) rolls the write back.
TEST_P(StoreTest, AuditRowCommitsWithItsWrite) {
  AuditContext audit;
  audit.row.identity = "station-7"; audit.row.role = "station"; audit.row.peer = "ipv4:127.0.0.1:1";
  audit.row.request_id = "r1"; audit.row.rpc = "IngestHfResults"; audit.row.serial = "IPM-A";
  audit.detail = [](int64_t id, bool replayed) { return (replayed ? "replayed run " : "run ") + std::to_string(id); };
  auto run = store_->IngestHfRun({"IPM-A", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3), "", {}, 0, "k1", nullptr,
                                 &audit);
  ASSERT_TRUE(run.ok()) << run.status();
  bool replayed = false;
  ASSERT_TRUE(store_->IngestHfRun({"IPM-A", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3), "", {}, 0, "k1",
                                  &replayed, &audit)
                  .ok());
  EXPECT_TRUE(replayed);
  CalibrationRow c;
  c.serial = "IPM-A"; c.model = "analytic"; c.verdict = "pass"; c.calibration_json = "{}";
  audit.row.rpc = "Fit";
  audit.detail = [](int64_t v, bool) { return "version " + std::to_string(v); };
  ASSERT_EQ(*store_->AddCalibration(c, &audit), 1);
  audit.row.rpc = "Release";
  audit.detail = nullptr;
  audit.row.detail = "released";
  ASSERT_TRUE(store_->Release("IPM-A", 1, "rel", &audit).ok());
  auto rows = store_->AuditOf("IPM-A");
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 4u);
  EXPECT_EQ((*rows)[0].detail, "run " + std::to_string(*run));
  EXPECT_EQ((*rows)[1].detail, "replayed run " + std::to_string(*run));
  EXPECT_EQ((*rows)[2].detail, "version 1");
  EXPECT_EQ((*rows)[3].detail, "released");
  EXPECT_EQ((*rows)[3].identity, "station-7");
  EXPECT_FALSE((*rows)[3].utc.empty());
  // Refused writes: no audit row.
  EXPECT_EQ(store_->Release("IPM-A", 1, "rel", &audit).code(), absl::StatusCode::kAlreadyExists);
  EXPECT_EQ(store_->Release("IPM-A", 9, "rel", &audit).code(), absl::StatusCode::kNotFound);
  c.verdict = "fail: residual";
  ASSERT_EQ(*store_->AddCalibration(c), 2);   // no audit context: no row
  EXPECT_EQ(store_->Release("IPM-A", 2, "rel", &audit).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->AuditOf("IPM-A")->size(), 4u);
  if (!SeparateConnections()) return;
  const bool pg = GetParam() == Backend::kPostgres;
  ASSERT_TRUE(RawSql(pg ? "CREATE FUNCTION refuse_audit() RETURNS trigger LANGUAGE plpgsql AS "
                          "$$BEGIN RAISE EXCEPTION 'audit insert refused'; END$$; "
                          "CREATE TRIGGER audit_refuse BEFORE INSERT ON audit FOR EACH ROW EXECUTE FUNCTION refuse_audit()"
                        : "CREATE TRIGGER audit_refuse BEFORE INSERT ON audit "
                          "BEGIN SELECT RAISE(ABORT, 'audit insert refused'); END"));
  c.verdict = "pass";
  EXPECT_FALSE(store_->AddCalibration(c, &audit).ok());
  EXPECT_EQ(store_->GetCalibration("IPM-A", 0)->version, 2) << "the version must roll back with its audit row";
  EXPECT_EQ(store_->AllChainRows()->size(), 2u);
  EXPECT_FALSE(store_->IngestHfRun({"IPM-A", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(4), "", {}, 0, "k2",
                                   nullptr, &audit)
                   .ok());
  EXPECT_EQ(store_->AllRuns()->size(), 1u) << "the run must roll back with its audit row";
  ASSERT_TRUE(store_->AddCalibration(c).ok());   // v3, without audit: unaffected by the trigger
  EXPECT_FALSE(store_->Release("IPM-A", 3, "rel", &audit).ok());
  EXPECT_FALSE(*store_->IsReleased("IPM-A", 3)) << "the release must roll back with its audit row";
  EXPECT_EQ(store_->AuditOf("IPM-A")->size(), 4u);
}

// The hash chain over calibration versions: intact after normal use; a
// verdict edited behind the store's back (triggers dropped) is found with
// serial and version, and so is a removed version.
TEST_P(StoreTest, TamperingWithACalibrationIsDetected) {
  ASSERT_TRUE(store_->IngestHfRun({"IPM-T", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3)).ok());
  CalibrationRow c;
  c.serial = "IPM-T"; c.model = "spline4"; c.psi_pm_wb = 0.0114 + 1e-17; c.rms_relative = 1.0 / 3.0;
  c.calibration_json = "{\"params\": [1, 2, 3]}";
  c.verdict = "pass";
  ASSERT_TRUE(store_->AddCalibration(c).ok());
  c.verdict = "fail: fit residual 3 %";
  ASSERT_TRUE(store_->AddCalibration(c).ok());
  c.verdict = "pass";
  ASSERT_TRUE(store_->AddCalibration(c).ok());
  auto ok = VerifyChains(*store_);
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_EQ(ok->chained, 3);
  EXPECT_TRUE(ok->problems.empty());
  if (!SeparateConnections()) return;
  const bool pg = GetParam() == Backend::kPostgres;
  ASSERT_TRUE(RawSql(pg ? "ALTER TABLE calibrations DISABLE TRIGGER USER" : "DROP TRIGGER calibrations_no_update"));
  ASSERT_TRUE(RawSql("UPDATE calibrations SET verdict = 'pass' WHERE serial = 'IPM-T' AND version = 2"));
  auto bad = VerifyChains(*store_);
  ASSERT_TRUE(bad.ok());
  ASSERT_EQ(bad->problems.size(), 1u);
  EXPECT_EQ(bad->problems[0], "IPM-T v2: row changed after it was stored");
  ASSERT_TRUE(RawSql(pg ? "DELETE FROM calibrations WHERE serial = 'IPM-T' AND version = 3"
                        : "DROP TRIGGER calibrations_no_delete"));
  if (!pg) {
    ASSERT_TRUE(RawSql("DELETE FROM calibrations WHERE serial = 'IPM-T' AND version = 3"));
  }
  auto gone = VerifyChains(*store_);
  ASSERT_TRUE(gone.ok());
  EXPECT_EQ(gone->problems.size(), 2u);
  EXPECT_EQ(gone->problems.back(), "IPM-T v3: calibration row removed");
}

// SQL that lets a test edit rows the triggers protect: per backend, turn
// the triggers of `tables` off (PostgreSQL) or drop them (SQLite).
std::string DropGuards(bool pg, const std::vector<std::string>& tables) {
  std::string sql;
  for (const auto& t : tables) {
    if (pg) {
      sql += "ALTER TABLE " + t + " DISABLE TRIGGER USER; ";
    } else if (t == "calibrations") {
      sql += "DROP TRIGGER calibrations_no_update; DROP TRIGGER calibrations_no_delete; ";
    } else if (t == "calibration_chain") {
      sql += "DROP TRIGGER chain_no_update; DROP TRIGGER chain_no_delete; ";
    } else {
      sql += "DROP TRIGGER " + t + "_no_update; DROP TRIGGER " + t + "_no_delete; ";
    }
  }
  return sql;
}

CalibrationRow Version(const std::string& serial, const std::string& verdict) {
  CalibrationRow c;
  c.serial = serial; c.model = "spline4"; c.psi_pm_wb = 0.0114; c.rms_relative = 0.004;
  c.calibration_json = "{\"params\": [1, 2]}"; c.verdict = verdict;
  return c;
}

// Releases join a hash chain of their own: normal releases verify; a
// release inserted straight into the table (its version failing, so the
// service would never release it) is named by VerifyChains, and
// VerifyReleasedVersion -- what a flasher's export runs -- refuses it while
// still passing the honest release; a release edited with the triggers
// dropped is named too.
TEST_P(StoreTest, ReleasesAreChained) {
  ASSERT_TRUE(store_->IngestHfRun({"IPM-X", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3)).ok());
  ASSERT_TRUE(store_->IngestHfRun({"IPM-Y", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3)).ok());
  ASSERT_EQ(*store_->AddCalibration(Version("IPM-X", "pass")), 1);
  ASSERT_EQ(*store_->AddCalibration(Version("IPM-X", "fail: fit residual 3 %")), 2);
  ASSERT_EQ(*store_->AddCalibration(Version("IPM-Y", "pass")), 1);
  ASSERT_TRUE(store_->Release("IPM-X", 1, "rel").ok());
  ASSERT_TRUE(store_->Release("IPM-Y", 1, "rel").ok());
  auto links = store_->AllReleaseLinks();
  ASSERT_TRUE(links.ok()) << links.status();
  ASSERT_EQ(links->size(), 2u);
  EXPECT_EQ(links->at(0).seq, 1);
  EXPECT_EQ(links->at(0).prev_sha256, "");
  EXPECT_EQ(links->at(1).prev_sha256, links->at(0).row_sha256) << "one chain across serials";
  EXPECT_EQ(links->at(0).calibration_sha256, store_->ChainLink("IPM-X", 1)->row_sha256);
  EXPECT_EQ(store_->ReleaseLinkAt(0)->serial, "IPM-Y");
  EXPECT_EQ(store_->ReleaseLink("IPM-X", 1)->seq, 1);
  EXPECT_EQ(store_->ReleaseLink("IPM-X", 2).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store_->GetRelease("IPM-X", 1)->released_by, "rel");
  EXPECT_EQ(store_->GetRelease("IPM-X", 2).status().code(), absl::StatusCode::kNotFound);
  auto ok = VerifyChains(*store_);
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_TRUE(ok->problems.empty()) << ok->problems.front();
  EXPECT_EQ(ok->releases_chained, 2);
  EXPECT_TRUE(VerifyReleasedVersion(*store_, "IPM-X", 1).ok());
  EXPECT_EQ(VerifyReleasedVersion(*store_, "IPM-X", 2).code(), absl::StatusCode::kFailedPrecondition)
      << "not released";
  if (!SeparateConnections()) return;
  const bool pg = GetParam() == Backend::kPostgres;
  // Behind the service: the failing version 2 made flashable by an INSERT
  // (no trigger guards INSERT on releases).
  ASSERT_TRUE(RawSql("INSERT INTO releases (serial, version, released_by, released_utc) "
                     "VALUES ('IPM-X', 2, 'someone', '2030-01-01T00:00:00Z')"));
  EXPECT_TRUE(*store_->IsReleased("IPM-X", 2)) << "the row is there, as a flasher's lookup sees it";
  auto bad = VerifyChains(*store_);
  ASSERT_TRUE(bad.ok());
  ASSERT_EQ(bad->problems.size(), 2u);
  EXPECT_EQ(bad->problems[0], "IPM-X v2: release without a chain link (inserted around the service)");
  EXPECT_EQ(bad->problems[1],
            "IPM-X v2: released with verdict 'fail: fit residual 3 %' (only 'pass' is ever released by the service)");
  const absl::Status refused = VerifyReleasedVersion(*store_, "IPM-X", 2);
  EXPECT_EQ(refused.code(), absl::StatusCode::kDataLoss) << refused;
  EXPECT_NE(refused.message().find("IPM-X v2: release without a chain link"), std::string::npos) << refused;
  EXPECT_TRUE(VerifyReleasedVersion(*store_, "IPM-Y", 1).ok()) << "the honest release still passes";
  // A release edited with its triggers gone.
  ASSERT_TRUE(RawSql(DropGuards(pg, {"releases"}) +
                     "UPDATE releases SET released_by = 'admin' WHERE serial = 'IPM-Y' AND version = 1"));
  auto edited = VerifyChains(*store_);
  ASSERT_TRUE(edited.ok());
  EXPECT_NE(std::find(edited->problems.begin(), edited->problems.end(),
                      "IPM-Y v1 (release #2): release changed after it was stored"),
            edited->problems.end());
  EXPECT_EQ(VerifyReleasedVersion(*store_, "IPM-Y", 1).code(), absl::StatusCode::kDataLoss);
}

// The defect an anchor closes: the newest version deleted together with its
// chain link leaves a chain that verifies. A head recorded before
// (CurrentChainHead, what `fluxcal admin anchor` writes) names it, and the
// newest release removed with its link likewise.
TEST_P(StoreTest, AnchorNamesARemovedNewestVersionAndRelease) {
  ASSERT_TRUE(store_->IngestHfRun({"IPM-A", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3)).ok());
  ASSERT_TRUE(store_->IngestHfRun({"IPM-B", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3)).ok());
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(store_->AddCalibration(Version("IPM-A", "pass")).ok());
  ASSERT_TRUE(store_->AddCalibration(Version("IPM-B", "pass")).ok());
  ASSERT_TRUE(store_->Release("IPM-A", 2, "rel").ok());
  ASSERT_TRUE(store_->Release("IPM-A", 3, "rel").ok());
  auto head = CurrentChainHead(*store_);
  ASSERT_TRUE(head.ok()) << head.status();
  ASSERT_EQ(head->calibrations.size(), 2u);
  EXPECT_EQ(head->calibrations[0].serial, "IPM-A");
  EXPECT_EQ(head->calibrations[0].version, 3);
  EXPECT_EQ(head->calibrations[0].row_sha256, store_->ChainLink("IPM-A", 3)->row_sha256);
  EXPECT_EQ(head->release_seq, 2);
  EXPECT_EQ(head->digest_sha256, ChainHeadDigest(*head));
  EXPECT_EQ(head->digest_sha256.size(), 64u);
  auto same = VerifyChains(*store_, &*head, "the anchor");
  ASSERT_TRUE(same.ok());
  EXPECT_TRUE(same->problems.empty());
  EXPECT_EQ(same->anchored, 3);
  if (!SeparateConnections()) return;
  const bool pg = GetParam() == Backend::kPostgres;
  // The newest release and its link, then the newest version of IPM-A with
  // its link: every remaining link still verifies.
  ASSERT_TRUE(RawSql(DropGuards(pg, {"releases", "release_chain", "calibrations", "calibration_chain"}) +
                     "DELETE FROM release_chain WHERE seq = 2; "
                     "DELETE FROM releases WHERE serial = 'IPM-A' AND version = 3; "
                     "DELETE FROM calibration_chain WHERE serial = 'IPM-A' AND version = 3; "
                     "DELETE FROM calibrations WHERE serial = 'IPM-A' AND version = 3"));
  auto blind = VerifyChains(*store_);
  ASSERT_TRUE(blind.ok());
  EXPECT_TRUE(blind->problems.empty()) << "the chains alone cannot see a removed head: " << blind->problems.front();
  auto anchored = VerifyChains(*store_, &*head, "the anchor");
  ASSERT_TRUE(anchored.ok());
  ASSERT_EQ(anchored->problems.size(), 2u);
  EXPECT_EQ(anchored->problems[0],
            "IPM-A v3: removed after the anchor (row and chain link; the newest stored is v2)");
  EXPECT_EQ(anchored->problems[1], "IPM-A v3 (release #2): removed after the anchor (release chain link)");
  EXPECT_EQ(anchored->anchored, 1) << "IPM-B v1 is still as anchored";
}

// Commands that only read open with create = false: a path that does not
// exist, an empty file and a database without fluxcal's tables are refused
// and left as they were.
TEST_P(StoreTest, OpenWithoutCreateRefusesWhatIsNotAStore) {
  if (GetParam() == Backend::kPostgres) {
    ASSERT_TRUE(pg_->CreateDatabase(db_ + "_empty"));
    auto none = Store::Open(pg_->Url(db_ + "_empty"), {.create = false});
    EXPECT_EQ(none.status().code(), absl::StatusCode::kNotFound) << none.status();
    EXPECT_NE(none.status().message().find("holds no fluxcal store"), std::string::npos) << none.status();
    EXPECT_EQ(pg_->Scalar(db_ + "_empty", "SELECT COUNT(*) FROM pg_tables WHERE schemaname = 'public'"), "0");
  } else {
    const std::string missing = (fs::temp_directory_path() / ("fluxcal_typo_" + std::to_string(::getpid()) + ".db")).string();
    fs::remove(missing);
    auto none = Store::Open(missing, {.create = false});
    EXPECT_EQ(none.status().code(), absl::StatusCode::kNotFound);
    EXPECT_NE(none.status().message().find("no store at '" + missing + "'"), std::string::npos) << none.status();
    EXPECT_FALSE(fs::exists(missing)) << "a read-only open must not create the file";
    std::ofstream(missing).close();
    auto empty = Store::Open("sqlite:" + missing, {.create = false});
    EXPECT_EQ(empty.status().code(), absl::StatusCode::kNotFound);
    EXPECT_NE(empty.status().message().find("holds no fluxcal store"), std::string::npos) << empty.status();
    EXPECT_EQ(fs::file_size(missing), 0u) << "the empty file must stay empty";
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(missing + sfx);
  }
  if (SeparateConnections()) {
    store_.reset();
    auto existing = Store::Open(url_, {.create = false});
    ASSERT_TRUE(existing.ok()) << existing.status();
    store_ = std::move(*existing);
  }
}

// A store written at schema v6 (releases without links) upgrades to v7: the
// migration links the releases already stored, oldest first, so the chain
// starts complete and any later unlinked release is a problem.
TEST_P(StoreTest, MigrationToV7LinksTheReleasesAlreadyStored) {
  if (!SeparateConnections()) GTEST_SKIP() << "needs a second database";
  const bool pg = GetParam() == Backend::kPostgres;
  std::string url;
  std::function<bool(const std::string&)> raw;
  std::string old_path;
  if (pg) {
    ASSERT_TRUE(pg_->CreateDatabase(db_ + "_v6"));
    url = pg_->Url(db_ + "_v6");
    raw = [&](const std::string& sql) { return pg_->Sql(db_ + "_v6", sql); };
  } else {
    old_path = path_ + ".v6";
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(old_path + sfx);
    url = old_path;
    raw = [&](const std::string& sql) {
      auto db = Database::Open(old_path);
      return db.ok() && (*db)->Exec(sql).ok();
    };
  }
  const auto& migrations = pg ? PostgresMigrations() : SqliteMigrations();
  ASSERT_EQ(migrations.size(), static_cast<size_t>(kSchemaVersion));
  // What a v6 store holds: a motor, two chained versions, two releases.
  ASSERT_TRUE(fluxcal::testing::OldSchemaWithMotor(raw, migrations, 6));
  std::string prev;
  for (int v = 1; v <= 2; ++v) {
    CalibrationRow c = Version("IPM-OLD", "pass");
    c.version = v;
    c.created_utc = "2024-01-0" + std::to_string(v + 1) + "T00:00:00Z";
    const std::string sha = CalibrationRowSha256(prev, c);
    ASSERT_TRUE(raw("INSERT INTO calibrations (serial, version, run_id, created_utc, model, psi_pm_wb, rms_relative, "
                    "verdict, calibration_json) VALUES ('IPM-OLD', " + std::to_string(v) + ", NULL, '" +
                    c.created_utc + "', 'spline4', 0.0114, 0.004, 'pass', '{\"params\": [1, 2]}')"));
    ASSERT_TRUE(raw("INSERT INTO calibration_chain (serial, version, prev_sha256, row_sha256) VALUES ('IPM-OLD', " +
                    std::to_string(v) + ", '" + prev + "', '" + sha + "')"));
    prev = sha;
  }
  ASSERT_TRUE(raw("INSERT INTO releases (serial, version, released_by, released_utc) VALUES "
                  "('IPM-OLD', 2, 'rel', '2024-02-01T00:00:00Z'), ('IPM-OLD', 1, 'rel', '2024-01-15T00:00:00Z')"));
  // A read-only open (verify-db) of the older store migrates it too.
  auto upgraded = Store::Open(url, {.create = false});
  ASSERT_TRUE(upgraded.ok()) << upgraded.status();
  EXPECT_EQ(*(*upgraded)->SchemaVersion(), kSchemaVersion);
  auto after = VerifyChains(**upgraded);
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_TRUE(after->problems.empty()) << after->problems.front();
  EXPECT_EQ(after->chained, 2);
  EXPECT_EQ(after->releases_chained, 2);
  auto links = (*upgraded)->AllReleaseLinks();
  ASSERT_TRUE(links.ok());
  ASSERT_EQ(links->size(), 2u);
  EXPECT_EQ(links->at(0).version, 1) << "linked in release order";
  EXPECT_EQ(links->at(1).version, 2);
  EXPECT_TRUE(VerifyReleasedVersion(**upgraded, "IPM-OLD", 2).ok());
  upgraded->reset();
  if (!old_path.empty()) {
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(old_path + sfx);
  }
}

// Writers on separate connections (separate Store objects, as separate
// server processes have) fit one serial at once: versions 1..N, each once.
TEST_P(StoreTest, ConcurrentVersionsAreUniqueAndGapFree) {
  ASSERT_TRUE(store_->IngestHfRun({"IPM-V", 4, 0.011, 0.0114, ""}, "st", "hf_run", Points(3)).ok());
  constexpr int kWriters = 6, kEach = 5;
  std::vector<std::unique_ptr<Store>> stores;
  for (int w = 0; w < kWriters; ++w) {
    if (!SeparateConnections()) break;
    auto s = Store::Open(url_);
    ASSERT_TRUE(s.ok()) << s.status();
    stores.push_back(std::move(*s));
  }
  std::vector<std::vector<int>> got(kWriters);
  std::atomic<int> errors{0};
  std::vector<std::thread> th;
  for (int w = 0; w < kWriters; ++w) {
    th.emplace_back([&, w] {
      Store& s = stores.empty() ? *store_ : *stores[w];
      for (int k = 0; k < kEach; ++k) {
        CalibrationRow c;
        c.serial = "IPM-V"; c.model = "analytic"; c.verdict = "pass"; c.calibration_json = "{}";
        auto v = s.AddCalibration(c);
        if (v.ok()) got[w].push_back(*v); else ++errors;
      }
    });
  }
  for (auto& t : th) t.join();
  EXPECT_EQ(errors.load(), 0);
  std::set<int> all;
  size_t n = 0;
  for (const auto& g : got) { all.insert(g.begin(), g.end()); n += g.size(); }
  EXPECT_EQ(n, all.size()) << "duplicate version";
  ASSERT_EQ(all.size(), static_cast<size_t>(kWriters * kEach));
  EXPECT_EQ(*all.begin(), 1);
  EXPECT_EQ(*all.rbegin(), kWriters * kEach) << "gap in versions";
  EXPECT_EQ(store_->GetCalibration("IPM-V", 0)->version, kWriters * kEach);
}

TEST_P(StoreTest, ListHistoryAndLatest) {
  for (const char* s : {"A-1", "A-2", "B-1"}) {
    ASSERT_TRUE(store_->IngestHfRun({s, 4, 0.01, 0.01, ""}, "st", "hf_run", Points(2)).ok());
  }
  EXPECT_EQ(store_->ListMotors("A-", false, 0, 10)->size(), 2u);
  EXPECT_EQ(store_->ListMotors("", false, 1, 1)->at(0).serial, "A-2");
  CalibrationRow c;
  c.serial = "A-2"; c.model = "analytic"; c.verdict = "fail: residual"; c.calibration_json = "{}";
  ASSERT_TRUE(store_->AddCalibration(c).ok());
  auto failed = store_->ListMotors("", true, 0, 10);
  ASSERT_EQ(failed->size(), 1u);
  EXPECT_EQ(failed->at(0).serial, "A-2");
  EXPECT_EQ(failed->at(0).latest_version, 1);
  EXPECT_EQ(failed->at(0).runs, 1);
  auto h = store_->History("A-2");
  ASSERT_TRUE(h.ok());
  ASSERT_EQ(h->size(), 2u);
  const auto& cal = h->at(0).kind == "calibration" ? h->at(0) : h->at(1);
  EXPECT_EQ(cal.kind, "calibration");
  EXPECT_EQ(cal.version, 1);
  EXPECT_EQ(cal.detail, "analytic fail: residual");
  EXPECT_EQ(store_->History("Z").status().code(), absl::StatusCode::kNotFound);
  auto latest = store_->LatestCalibrations();
  ASSERT_EQ(latest->size(), 1u);
  EXPECT_EQ(latest->at(0).serial, "A-2");
}

TEST_P(StoreTest, WholeStoreExportAndImport) {
  ASSERT_TRUE(store_->IngestHfRun({"W-1", 4, 0.01, 0.02, ""}, "st", "recording", Points(3), "sha-w", {1, 2, 3}, 3).ok());
  CalibrationRow c;
  c.serial = "W-1"; c.model = "analytic"; c.verdict = "pass"; c.calibration_json = "{\"a\":1}"; c.run_id = 1;
  ASSERT_TRUE(store_->AddCalibration(c).ok());
  auto runs = store_->AllRuns();
  ASSERT_EQ(runs->size(), 1u);
  EXPECT_EQ(runs->at(0).recording_sha256, "sha-w");
  EXPECT_EQ(store_->AllMotors()->size(), 1u);
  EXPECT_EQ(store_->AllCalibrations()->size(), 1u);
  // Import keeps ids, versions and timestamps; later runs continue after them.
  RunRow r{41, "W-2", "old", "hf_run", "", "2020-01-02T03:04:05Z", ""};
  ASSERT_TRUE(store_->ImportMotor({"W-2", 3, 0.5, 0.25, "2020-01-01T00:00:00Z"}).ok());
  ASSERT_TRUE(store_->ImportRun(r, Points(4), nullptr).ok());
  CalibrationRow ic = c;
  ic.serial = "W-2"; ic.version = 7; ic.run_id = 41; ic.created_utc = "2020-01-03T00:00:00Z";
  ASSERT_TRUE(store_->ImportCalibration(ic).ok());
  EXPECT_EQ(store_->GetCalibration("W-2", 0)->created_utc, "2020-01-03T00:00:00Z");
  EXPECT_EQ(store_->RunPoints(41)->size(), 4u);
  EXPECT_EQ(store_->GetMotor("W-2")->created_utc, "2020-01-01T00:00:00Z");
  auto next = store_->IngestHfRun({"W-2", 3, 0.5, 0.25, ""}, "st", "hf_run", Points(1));
  ASSERT_TRUE(next.ok()) << next.status();
  EXPECT_GT(*next, 41);
  EXPECT_EQ(*store_->AddCalibration(ic), 8);
  // Idempotency keys, releases, audit rows and chain links keep their
  // values; a retry with an imported key replays, later audit rows continue
  // after the imported ids.
  RunRow keyed{60, "W-2", "old", "hf_run", "", "2020-01-02T03:04:06Z", "key-60"};
  ASSERT_TRUE(store_->ImportRun(keyed, Points(2), nullptr).ok());
  EXPECT_EQ(store_->AllRuns()->back().idempotency_key, "key-60");
  bool replayed = false;
  EXPECT_EQ(*store_->IngestHfRun({"W-2", 3, 0.5, 0.25, ""}, "st", "hf_run", Points(2), "", {}, 0, "key-60", &replayed),
            60);
  EXPECT_TRUE(replayed);
  ASSERT_TRUE(store_
                  ->ImportTrail({{"W-2", 7, "rel", "2020-01-04T00:00:00Z"}},
                                {{90, "2020-01-04T00:00:01Z", "rel", "release", "peer", "req", "Release", "W-2",
                                  "released version 7"}},
                                {{"W-2", 7, "", "abc"}}, {{1, "W-2", 7, "abc", "", "def"}})
                  .ok());
  EXPECT_TRUE(*store_->IsReleased("W-2", 7));
  auto rlinks = store_->AllReleaseLinks();
  ASSERT_TRUE(rlinks.ok()) << rlinks.status();
  ASSERT_EQ(rlinks->size(), 1u);
  EXPECT_EQ(rlinks->at(0).row_sha256, "def");
  EXPECT_EQ(store_->ReleaseLink("W-2", 7)->calibration_sha256, "abc");
  ASSERT_EQ(store_->AllReleases()->size(), 1u);
  EXPECT_EQ(store_->AllReleases()->at(0).released_utc, "2020-01-04T00:00:00Z");
  AuditRow later;
  later.identity = "x"; later.role = "admin"; later.rpc = "Fit"; later.serial = "W-2";
  ASSERT_TRUE(store_->AppendAudit(later).ok());
  auto trail = store_->AllAudit();
  ASSERT_EQ(trail->size(), 2u);
  EXPECT_EQ(trail->at(0).id, 90);
  EXPECT_EQ(trail->at(0).utc, "2020-01-04T00:00:01Z");
  EXPECT_GT(trail->at(1).id, 90);
  bool found = false;
  const auto links = store_->AllChainRows();
  ASSERT_TRUE(links.ok());
  for (const auto& l : *links) found |= l.serial == "W-2" && l.version == 7 && l.row_sha256 == "abc";
  EXPECT_TRUE(found);
}

INSTANTIATE_TEST_SUITE_P(Backends, StoreTest,
                         ::testing::Values(Backend::kSqliteMemory, Backend::kSqliteFile, Backend::kPostgres), Name);

TEST(Transaction, RollsBackOnError) {
  auto db = Database::Open(":memory:");
  ASSERT_TRUE(db.ok());
  ASSERT_TRUE((*db)->Exec("CREATE TABLE t (x INTEGER)").ok());
  auto st = (*db)->Transaction([&]() -> absl::Status {
    auto ins = (*db)->Prepare("INSERT INTO t (x) VALUES (?)");
    if (!ins.ok()) return ins.status();
    (void)ins->Bind(1, int64_t{7});
    if (auto r = ins->Step(); !r.ok()) return r.status();
    return absl::InvalidArgumentError("points[3].ld_h: bad");   // fails after the insert
  });
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  auto q = (*db)->Prepare("SELECT COUNT(*) FROM t");
  ASSERT_TRUE(q.ok());
  ASSERT_TRUE(*q->Step());
  EXPECT_EQ(q->Int(0), 0) << "the failed transaction left a row behind";
}

// The dialects are complete data: every schema version on both, and the
// clauses the shared SQL takes from them where the database needs one.
TEST(Dialects, EachHoldsEveryMigrationAndTheClausesItNeeds) {
  for (const Dialect* d : {&SqliteDialect(), &PostgresDialect()}) {
    SCOPED_TRACE(d->name);
    EXPECT_EQ(d->migrations.size(), static_cast<size_t>(kSchemaVersion));
    EXPECT_FALSE(d->begin.empty());
    EXPECT_FALSE(d->table_exists.empty());
    EXPECT_FALSE(d->unlock_calibrations.empty());
    EXPECT_FALSE(d->relock_calibrations.empty());
  }
  // PostgreSQL has no file lock: row and advisory locks do its ordering.
  EXPECT_FALSE(PostgresDialect().for_update.empty());
  EXPECT_FALSE(PostgresDialect().advisory_lock.empty());
  EXPECT_EQ(SqliteDialect().begin, "BEGIN IMMEDIATE");
}

// The seam on each backend: bound parameters in order (a `?` inside a
// literal is no placeholder), rows back (RETURNING too), a rolled-back
// transaction leaves nothing, cells read as stored.
void CheckSeam(SqlPool& pool) {
  auto st = pool.WithSource([](SqlSource& s) -> absl::Status {
    if (auto e = s.ExecScript("CREATE TABLE seam_t (id INTEGER PRIMARY KEY, x DOUBLE PRECISION, name TEXT, b "
                              + std::string(s.dialect().name == "sqlite" ? "BLOB" : "BYTEA") + ")");
        !e.ok()) {
      return e;
    }
    auto id = s.QueryOne("INSERT INTO seam_t (id, x, name, b) VALUES (?,?,?,?) RETURNING id",
                         {int64_t{1}, 0.1, std::string("it's ?"), BytesOrNull("ab")}, "no id");
    if (!id.ok()) return id.status();
    EXPECT_EQ(id->Int(0), 1);
    if (auto e = s.Begin(); !e.ok()) return e;
    if (auto e = s.InsertRows("seam_t", {"id", "x", "name"}, {{int64_t{2}, 2.5, std::string("a\tb")},
                                                              {int64_t{3}, nullptr, nullptr}});
        !e.ok()) {
      return e;
    }
    auto inside = s.Query("SELECT name FROM seam_t WHERE id = 2");
    if (!inside.ok()) return inside.status();
    EXPECT_EQ(inside->size(), 1u);
    if (!inside->empty()) EXPECT_EQ(inside->front().Text(0), "a\tb");
    if (auto e = s.Rollback(); !e.ok()) return e;
    auto rows = s.Query("SELECT x, name, b, id, 'lit?' FROM seam_t WHERE name = ?", {std::string("it's ?")});
    if (!rows.ok()) return rows.status();
    EXPECT_EQ(rows->size(), 1u);
    auto all = s.Query("SELECT COUNT(*) FROM seam_t");
    if (!all.ok()) return all.status();
    EXPECT_EQ(all->front().Int(0), 1) << "the rolled-back rows are gone";
    if (rows->size() != 1) return absl::OkStatus();
    const SqlRow& r = rows->front();
    EXPECT_EQ(r.Double(0), 0.1);
    EXPECT_EQ(r.Text(1), "it's ?");
    EXPECT_EQ(r.Blob(2), (std::vector<uint8_t>{97, 98}));
    EXPECT_EQ(r.Text(3), "1");
    EXPECT_EQ(r.Text(4), "lit?");
    return absl::OkStatus();
  });
  EXPECT_TRUE(st.ok()) << st;
}

TEST(SqlSeam, Sqlite) {
  auto pool = OpenSqlitePool(":memory:", true);
  ASSERT_TRUE(pool.ok()) << pool.status();
  EXPECT_EQ((*pool)->dialect().name, "sqlite");
  CheckSeam(**pool);
}

TEST(SqlSeam, PostgreSQL) {
  std::string why;
  auto* pg = fluxcal::testing::SharedPgCluster(&why);
  FLUXCAL_PG_OR_SKIP(pg, why, "PostgreSQL seam run skipped");
#ifdef FLUXCAL_WITH_POSTGRESQL
  ASSERT_TRUE(pg->CreateDatabase("seam"));
  auto pool = OpenPostgresPool(pg->Url("seam"), 2);
  ASSERT_TRUE(pool.ok()) << pool.status();
  EXPECT_EQ((*pool)->dialect().name, "postgresql");
  CheckSeam(**pool);
#endif
}

// A build without libpq refuses a PostgreSQL URL at open, saying why; a
// build with it tries to connect (and fails: nothing listens there).
TEST(StoreOpen, PostgresUrlSaysWhetherThisBuildHasPostgres) {
  auto s = Store::Open("postgresql://fluxcal@127.0.0.1:1/none?connect_timeout=1");
  ASSERT_FALSE(s.ok());
#ifdef FLUXCAL_WITH_POSTGRESQL
  EXPECT_EQ(s.status().code(), absl::StatusCode::kUnavailable) << s.status();
#else
  EXPECT_EQ(s.status().code(), absl::StatusCode::kUnimplemented) << s.status();
  EXPECT_NE(s.status().message().find("built without PostgreSQL"), std::string::npos) << s.status();
#endif
}

}  // namespace
}  // namespace fluxcal::storage
