// Store conformance: one suite, run on SQLite (":memory:" and a file) and on
// a real PostgreSQL server started in a temporary directory: migrations,
// all-or-nothing runs, exact round trips, immutable calibration versions
// (refused by the database itself), gap-free versions under concurrent
// writers on separate connections, listing, history, whole-store access.
#include "storage/store.h"

#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <set>
#include <thread>

#include "gtest/gtest.h"
#include "storage/sqlite.h"
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
    EXPECT_EQ((*pts)[k].reliable, in[k].reliable);
  }
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
  auto ok = VerifyCalibrationChain(*store_);
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_EQ(ok->chained, 3);
  EXPECT_TRUE(ok->problems.empty());
  if (!SeparateConnections()) return;
  const bool pg = GetParam() == Backend::kPostgres;
  ASSERT_TRUE(RawSql(pg ? "ALTER TABLE calibrations DISABLE TRIGGER USER" : "DROP TRIGGER calibrations_no_update"));
  ASSERT_TRUE(RawSql("UPDATE calibrations SET verdict = 'pass' WHERE serial = 'IPM-T' AND version = 2"));
  auto bad = VerifyCalibrationChain(*store_);
  ASSERT_TRUE(bad.ok());
  ASSERT_EQ(bad->problems.size(), 1u);
  EXPECT_EQ(bad->problems[0], "IPM-T v2: row changed after it was stored");
  ASSERT_TRUE(RawSql(pg ? "DELETE FROM calibrations WHERE serial = 'IPM-T' AND version = 3"
                        : "DROP TRIGGER calibrations_no_delete"));
  if (!pg) ASSERT_TRUE(RawSql("DELETE FROM calibrations WHERE serial = 'IPM-T' AND version = 3"));
  auto gone = VerifyCalibrationChain(*store_);
  ASSERT_TRUE(gone.ok());
  EXPECT_EQ(gone->problems.size(), 2u);
  EXPECT_EQ(gone->problems.back(), "IPM-T v3: calibration row removed");
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
  RunRow r{41, "W-2", "old", "hf_run", "", "2020-01-02T03:04:05Z"};
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
                                {{"W-2", 7, "", "abc"}})
                  .ok());
  EXPECT_TRUE(*store_->IsReleased("W-2", 7));
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

}  // namespace
}  // namespace fluxcal::storage
