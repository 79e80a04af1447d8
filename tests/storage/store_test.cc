// Store conformance, run on ":memory:" and on a file: migrations, all-or-
// nothing runs, immutable calibration versions, listing and history.
#include "storage/store.h"

#include <filesystem>

#include "gtest/gtest.h"
#include "storage/sqlite.h"

namespace fluxcal::storage {
namespace {

namespace fs = std::filesystem;

class StoreTest : public ::testing::TestWithParam<bool> {
 protected:
  void SetUp() override {
    if (GetParam()) {
      path_ = (fs::temp_directory_path() / ("fluxcal_store_" + std::to_string(::getpid()) + ".db")).string();
      fs::remove(path_);
    } else {
      path_ = ":memory:";
    }
    auto s = Store::Open(path_);
    ASSERT_TRUE(s.ok()) << s.status();
    store_ = std::move(*s);
  }
  void TearDown() override {
    store_.reset();
    if (GetParam()) {
      fs::remove(path_);
      fs::remove(path_ + "-wal");
      fs::remove(path_ + "-shm");
    }
  }
  std::vector<HfPointRow> Points(int n) {
    std::vector<HfPointRow> v;
    for (int k = 0; k < n; ++k) {
      HfPointRow p;
      p.point_id = "p" + std::to_string(k);
      p.id_a = -20.0 * k; p.iq_a = 40; p.ld_h = 1.8e-4; p.lq_h = 3.6e-4; p.ld_h_std = 1e-7; p.lq_h_std = 1e-7;
      v.push_back(p);
    }
    return v;
  }
  std::string path_;
  std::unique_ptr<Store> store_;
};

TEST_P(StoreTest, MigratesToCurrentSchema) {
  auto v = store_->SchemaVersion();
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(*v, kSchemaVersion);
  if (GetParam()) {
    store_.reset();
    auto again = Store::Open(path_);   // idempotent re-open
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(*(*again)->SchemaVersion(), kSchemaVersion);
    store_ = std::move(*again);
  }
}

TEST_P(StoreTest, RunAndPointsRoundTrip) {
  auto run = store_->IngestHfRun({"IPM-1", 4, 0.011, 0.0114}, "st1", "hf_run", Points(36));
  ASSERT_TRUE(run.ok()) << run.status();
  int64_t id = 0;
  auto pts = store_->LatestRunPoints("IPM-1", &id);
  ASSERT_TRUE(pts.ok());
  EXPECT_EQ(id, *run);
  ASSERT_EQ(pts->size(), 36u);
  EXPECT_DOUBLE_EQ((*pts)[5].id_a, -100.0);
  EXPECT_FALSE((*pts)[5].ldq_h.has_value());
  EXPECT_EQ(store_->LatestRunPoints("NOPE", &id).status().code(), absl::StatusCode::kNotFound);
}

TEST_P(StoreTest, CalibrationVersionsAreImmutable) {
  ASSERT_TRUE(store_->IngestHfRun({"IPM-2", 4, 0.011, 0.0114}, "st", "hf_run", Points(3)).ok());
  CalibrationRow c;
  c.serial = "IPM-2"; c.model = "analytic"; c.verdict = "pass"; c.calibration_json = "{}";
  EXPECT_EQ(*store_->AddCalibration(c), 1);
  c.verdict = "fail: x";
  EXPECT_EQ(*store_->AddCalibration(c), 2);
  EXPECT_EQ(store_->GetCalibration("IPM-2", 1)->verdict, "pass");
  EXPECT_EQ(store_->GetCalibration("IPM-2", 0)->version, 2);
  // The database itself refuses to change a stored version.
  auto db = Database::Open(path_);
  if (GetParam()) {
    ASSERT_TRUE(db.ok());
    EXPECT_FALSE((*db)->Exec("UPDATE calibrations SET verdict = 'pass' WHERE version = 2").ok());
    EXPECT_FALSE((*db)->Exec("DELETE FROM calibrations").ok());
  }
  EXPECT_EQ(store_->GetCalibration("IPM-2", 3).status().code(), absl::StatusCode::kNotFound);
}

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

TEST_P(StoreTest, ListAndHistory) {
  for (const char* s : {"A-1", "A-2", "B-1"}) ASSERT_TRUE(store_->IngestHfRun({s, 4, 0.01, 0.01}, "st", "hf_run", Points(2)).ok());
  EXPECT_EQ(store_->ListMotors("A-", false, 0, 10)->size(), 2u);
  EXPECT_EQ(store_->ListMotors("", false, 1, 1)->at(0).serial, "A-2");
  EXPECT_EQ(store_->History("Z").status().code(), absl::StatusCode::kNotFound);
}

INSTANTIATE_TEST_SUITE_P(MemoryAndFile, StoreTest, ::testing::Values(false, true));

}  // namespace
}  // namespace fluxcal::storage
