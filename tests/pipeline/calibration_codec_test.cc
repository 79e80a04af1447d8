// The binary calibration model (pipeline/calibration_codec.h) and the
// schema v8 migration that converts stored JSON to it: every model family
// round-trips bit for bit, the largest stays within 50 kB, and a store
// written before v8 (built here from the old migrations and raw SQL, on
// SQLite and, where installed, PostgreSQL) migrates, verifies and reads
// back the same calibrations.
#include "pipeline/calibration_codec.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>

#include "fitting/fit.h"
#include "fluxcal/v1/calibration_model.pb.h"
#include "gtest/gtest.h"
#include "identification/identify.h"
#include "io/sha256.h"
#include "nlohmann/json.hpp"
#include "pipeline/pipeline.h"
#include "pipeline/store.h"
#include "simulation/twin.h"
#include "storage/sqlite.h"
#include "tests/support/old_schema.h"
#include "tests/support/pg_cluster.h"

namespace fluxcal::pipeline {
namespace {

namespace fs = std::filesystem;

// The design limit of the stored form (issue 26): at most 50 kB a version.
constexpr size_t kMaxModelBytes = 50 * 1024;

// One simulated bench run (seeded noise, cross saturation) fitted with each
// model family by name.
const std::map<std::string, fit::Calibration>& Fits() {
  static const auto* fits = [] {
    auto* out = new std::map<std::string, fit::Calibration>;
    sim::TwinConfig cfg;
    cfg.seed = 26;
    cfg.sensors.noise_a = 0.08;
    cfg.effects.cross_saturation = 3e-5;
    auto r = sim::Simulate(cfg, sim::DefaultPlan());
    EXPECT_TRUE(r.ok()) << r.status();
    if (!r.ok()) return out;
    auto ids = ident::IdentifySet(r->set, {});
    EXPECT_TRUE(ids.ok()) << ids.status();
    if (!ids.ok()) return out;
    const fit::FitData data = fit::FitDataFromRecording(r->set, *ids);
    for (const char* model : {"analytic", "poly4", "spline3", "smooth", "smooth-asym"}) {
      fit::FitOptions o;
      o.model = model;
      auto cal = fit::Fit(data, o);
      EXPECT_TRUE(cal.ok()) << model << ": " << cal.status();
      if (cal.ok()) out->emplace(model, std::move(*cal));
    }
    return out;
  }();
  return *fits;
}

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(CalibrationCodec, EveryFamilyRoundTripsBitExact) {
  ASSERT_EQ(Fits().size(), 5u);
  size_t largest = 0;
  for (const auto& [model, cal] : Fits()) {
    SCOPED_TRACE(model);
    EXPECT_EQ(cal.family().Name(), model);
    // The covariance as the calibration holds it: symmetric, float values.
    const size_t n = cal.params().size();
    ASSERT_EQ(cal.covariance().size(), n * n);
    for (size_t r = 0; r < n; ++r) {
      for (size_t c = 0; c < n; ++c) {
        const double v = cal.covariance()[r * n + c];
        ASSERT_TRUE(SameBits(v, static_cast<double>(static_cast<float>(v)))) << "(" << r << "," << c << ")";
        ASSERT_TRUE(SameBits(v, cal.covariance()[c * n + r])) << "(" << r << "," << c << ")";
      }
    }
    // Calibration -> binary -> Calibration -> binary.
    const std::string bytes = EncodeCalibration(cal);
    auto back = DecodeCalibration(bytes);
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_TRUE(EncodeCalibration(*back) == bytes) << "binary -> Calibration -> binary differs";
    ASSERT_EQ(back->params().size(), n);
    for (size_t k = 0; k < n; ++k) EXPECT_TRUE(SameBits(back->params()[k], cal.params()[k])) << "param " << k;
    for (size_t k = 0; k < n * n; ++k) {
      ASSERT_TRUE(SameBits(back->covariance()[k], cal.covariance()[k])) << "covariance " << k;
    }
    // What a query answers is the same to the bit.
    for (auto [id, iq] : {std::pair{-10.0, 5.0}, {0.0, 0.0}, {-30.0, -20.0}}) {
      const auto a = cal.Predict(id, iq), b = back->Predict(id, iq);
      EXPECT_TRUE(SameBits(a.psi_d_wb, b.psi_d_wb) && SameBits(a.psi_q_wb, b.psi_q_wb) &&
                  SameBits(a.torque_nm_std, b.torque_nm_std) && SameBits(a.ldd_h_std, b.ldd_h_std))
          << "at id " << id << " A, iq " << iq << " A";
    }
    // JSON (as ToJson writes it) -> binary -> JSON: the same text.
    const std::string json = cal.ToJson().dump();
    auto model_pb = CalibrationJsonToModel(json);
    ASSERT_TRUE(model_pb.ok()) << model_pb.status();
    EXPECT_TRUE(*model_pb == bytes) << "JSON -> binary differs from Calibration -> binary";
    auto view = CalibrationModelToJson(*model_pb);
    ASSERT_TRUE(view.ok()) << view.status();
    EXPECT_EQ(view->dump(), json);
    std::printf("%-12s %4zu parameters: JSON %7zu bytes, binary %6zu bytes\n", model.c_str(), n, json.size(),
                bytes.size());
    EXPECT_LE(bytes.size(), kMaxModelBytes) << model << ": " << bytes.size() << " bytes";
    largest = std::max(largest, bytes.size());
  }
  // The largest family (smooth-asym: 181 parameters here) is the one the
  // 50 kB limit is about.
  EXPECT_GT(largest, 20000u) << "the largest family's model is " << largest << " bytes";
}

TEST(CalibrationCodec, JsonMembersTheCalibrationDoesNotHoldTravelAlong) {
  ASSERT_TRUE(Fits().count("poly4"));
  nlohmann::json j = Fits().at("poly4").ToJson();
  j["diagnosis"] = {{"format", "fluxcal.diagnosis.v1"}, {"verdict", "pass"}, {"findings", nlohmann::json::array()}};
  auto model_pb = CalibrationJsonToModel(j.dump());
  ASSERT_TRUE(model_pb.ok()) << model_pb.status();
  auto view = CalibrationModelToJson(*model_pb);
  ASSERT_TRUE(view.ok()) << view.status();
  EXPECT_EQ(view->dump(), j.dump());
}

TEST(CalibrationCodec, DoubleCovarianceIsReadAtFloatPrecision) {
  // A file written before the covariance was rounded: read, it is rounded
  // (the standard deviations agree to float precision), and from then on exact.
  ASSERT_TRUE(Fits().count("spline3"));
  const fit::Calibration& cal = Fits().at("spline3");
  nlohmann::json j = cal.ToJson();
  for (auto& v : j["covariance"]) v = v.get<double>() * (1 + 1e-12);
  auto read = fit::Calibration::FromJson(j);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->covariance(), cal.covariance());
  const auto a = cal.Predict(-10, 5), b = read->Predict(-10, 5);
  EXPECT_NEAR(b.torque_nm_std, a.torque_nm_std, 1e-6 * a.torque_nm_std);
}

// The magnet temperature facts (fit::Calibration::psi_pm_temp_coeff_per_k,
// magnet_reference_c and its spread) through every serialisation: binary
// and JSON, bit for bit; a calibration without them (every file and row
// written before they existed) reads back without them; out-of-range
// values are refused naming the field.
TEST(CalibrationCodec, MagnetTemperatureRoundTripsBitExact) {
  ASSERT_TRUE(Fits().count("poly4"));
  // The simulated set records 25 degC at every point and row.
  ASSERT_TRUE(Fits().at("poly4").magnet_reference_c().has_value());
  EXPECT_EQ(*Fits().at("poly4").magnet_reference_c(), 25.0);
  fit::Calibration cal = Fits().at("poly4");
  cal.set_psi_pm_temp_coeff_per_k(-0.0011);
  cal.set_magnet_reference(37.123456789012345, 12.5 + 1e-13);
  const std::string bytes = EncodeCalibration(cal);
  auto back = DecodeCalibration(bytes);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_TRUE(EncodeCalibration(*back) == bytes);
  ASSERT_TRUE(back->psi_pm_temp_coeff_per_k() && back->magnet_reference_c() && back->magnet_reference_spread_k());
  EXPECT_TRUE(SameBits(*back->psi_pm_temp_coeff_per_k(), -0.0011));
  EXPECT_TRUE(SameBits(*back->magnet_reference_c(), 37.123456789012345));
  EXPECT_TRUE(SameBits(*back->magnet_reference_spread_k(), 12.5 + 1e-13));
  const std::string json = cal.ToJson().dump();
  auto from_json = fit::Calibration::FromJson(nlohmann::json::parse(json));
  ASSERT_TRUE(from_json.ok()) << from_json.status();
  EXPECT_TRUE(EncodeCalibration(*from_json) == bytes) << "JSON -> Calibration -> binary differs";
  auto model_pb = CalibrationJsonToModel(json);
  ASSERT_TRUE(model_pb.ok()) << model_pb.status();
  EXPECT_TRUE(*model_pb == bytes);
  auto view = CalibrationModelToJson(*model_pb);
  ASSERT_TRUE(view.ok()) << view.status();
  EXPECT_EQ(view->dump(), json);
  // Without them: absent from both forms, and absent when read back.
  fit::Calibration none = cal;
  none.set_psi_pm_temp_coeff_per_k(std::nullopt);
  none.set_magnet_reference(std::nullopt, 3.0);   // a spread alone is dropped
  const nlohmann::json nj = none.ToJson();
  for (const char* key : {"psi_pm_temp_coeff_per_k", "magnet_reference_c", "magnet_reference_spread_k"}) {
    EXPECT_FALSE(nj.contains(key)) << key;
  }
  v1::CalibrationModel m;
  ASSERT_TRUE(m.ParseFromString(EncodeCalibration(none)));
  EXPECT_FALSE(m.has_psi_pm_temp_coeff_per_k() || m.has_magnet_reference_c() || m.has_magnet_reference_spread_k());
  auto none_back = DecodeCalibration(m.SerializeAsString());
  ASSERT_TRUE(none_back.ok()) << none_back.status();
  EXPECT_FALSE(none_back->psi_pm_temp_coeff_per_k() || none_back->magnet_reference_c() ||
               none_back->magnet_reference_spread_k());
  // Refused, naming the field.
  nlohmann::json bad = cal.ToJson();
  bad["psi_pm_temp_coeff_per_k"] = -0.11;   // %/K, not a relative change per kelvin
  auto refused = fit::Calibration::FromJson(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("field 'psi_pm_temp_coeff_per_k'"), std::string::npos)
      << refused.status();
  m.set_magnet_reference_spread_k(4.0);   // without a reference
  auto refused_pb = DecodeCalibration(m.SerializeAsString());
  ASSERT_FALSE(refused_pb.ok());
  EXPECT_NE(refused_pb.status().message().find("magnet_reference_spread_k"), std::string::npos) << refused_pb.status();
}

TEST(CalibrationCodec, RefusesWhatIsNotAModel) {
  EXPECT_FALSE(DecodeCalibration("not a message").ok());
  EXPECT_FALSE(DecodeCalibration("").ok()) << "an empty message has no pole pairs";
  EXPECT_FALSE(CalibrationJsonToModel("{\"params\": [1, 2]}").ok());
}

// ---- The v8 migration of a store written before it.

enum class Backend { kSqlite, kPostgres };

class MigrationTest : public ::testing::TestWithParam<Backend> {};

TEST_P(MigrationTest, OldJsonRowsConvertAndStillVerify) {
  ASSERT_TRUE(Fits().count("smooth") && Fits().count("analytic"));
  const bool pg = GetParam() == Backend::kPostgres;
  std::string url, path, why;
  std::function<bool(const std::string&)> raw;
  fluxcal::testing::PgCluster* cluster = nullptr;
  if (pg) {
    cluster = fluxcal::testing::SharedPgCluster(&why);
    FLUXCAL_PG_OR_SKIP(cluster, why, "PostgreSQL migration run skipped");
    ASSERT_TRUE(cluster->CreateDatabase("codec_v7"));
    url = cluster->Url("codec_v7");
    raw = [&](const std::string& sql) { return cluster->Sql("codec_v7", sql); };
  } else {
    path = (fs::temp_directory_path() / ("fluxcal_codec_v7_" + std::to_string(::getpid()) + ".db")).string();
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(path + sfx);
    url = path;
    raw = [&](const std::string& sql) {
      auto db = storage::Database::Open(path);
      return db.ok() && (*db)->Exec(sql).ok();
    };
  }
  // The layout before v8: migrations 1..6 as they are (v7 links the
  // releases already stored when the store opens).
  const auto& migrations = pg ? storage::PostgresMigrations() : storage::SqliteMigrations();
  ASSERT_TRUE(fluxcal::testing::OldSchemaWithMotor(raw, migrations, 6));
  // Versions as FitSerial stored them: the JSON with the covariance in full
  // double digits (scaled off float precision, as a fit's covariance was).
  auto legacy_json = [](const fit::Calibration& cal) {
    nlohmann::json j = cal.ToJson();
    for (auto& v : j["covariance"]) v = v.get<double>() * (1 + 1e-12);
    return j.dump();
  };
  struct Old {
    std::string model, json;
  };
  const std::vector<Old> olds = {{"smooth", legacy_json(Fits().at("smooth"))},
                                 {"analytic", legacy_json(Fits().at("analytic"))},
                                 // JSON the codec cannot read: stays JSON.
                                 {"analytic", "{\"params\": [1, 2]}"}};
  std::string prev;
  for (size_t k = 0; k < olds.size(); ++k) {
    storage::CalibrationRow c;
    c.serial = "IPM-OLD";
    c.version = static_cast<int>(k) + 1;
    c.created_utc = "2024-01-0" + std::to_string(k + 2) + "T00:00:00Z";
    c.model = olds[k].model;
    c.psi_pm_wb = 0.0114;
    c.rms_relative = 0.004;
    c.verdict = "pass";
    c.calibration_json = olds[k].json;
    const std::string sha = storage::CalibrationRowSha256(prev, c);
    ASSERT_TRUE(raw("INSERT INTO calibrations (serial, version, run_id, created_utc, model, psi_pm_wb, rms_relative, "
                    "verdict, calibration_json) VALUES ('IPM-OLD', " + std::to_string(c.version) + ", NULL, '" +
                    c.created_utc + "', '" + c.model + "', 0.0114, 0.004, 'pass', '" + c.calibration_json + "')"));
    ASSERT_TRUE(raw("INSERT INTO calibration_chain (serial, version, prev_sha256, row_sha256) VALUES ('IPM-OLD', " +
                    std::to_string(c.version) + ", '" + prev + "', '" + sha + "')"));
    prev = sha;
  }
  ASSERT_TRUE(raw("INSERT INTO releases (serial, version, released_by, released_utc) VALUES "
                  "('IPM-OLD', 1, 'rel', '2024-02-01T00:00:00Z')"));

  // Opened as fluxcal opens it (pipeline::OpenStore, read-only as verify-db
  // does): migrated to v8, JSON converted.
  auto store = OpenStore(url, /*create=*/false);
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ(*(*store)->SchemaVersion(), storage::kSchemaVersion);
  auto report = storage::VerifyChains(**store);
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_TRUE(report->problems.empty()) << report->problems.front();
  EXPECT_EQ(report->chained, 3);
  EXPECT_EQ(report->converted, 2);
  EXPECT_EQ(report->releases_chained, 1);
  EXPECT_TRUE(storage::VerifyReleasedVersion(**store, "IPM-OLD", 1).ok());
  auto conversions = (*store)->AllConversions();
  ASSERT_TRUE(conversions.ok());
  ASSERT_EQ(conversions->size(), 2u);
  EXPECT_EQ(conversions->at(0).json_sha256, io::Sha256Hex(olds[0].json)) << "the record names the JSON it replaced";
  // The migration says what it did in the audit trail.
  auto audit = (*store)->AllAudit();
  ASSERT_TRUE(audit.ok());
  ASSERT_EQ(audit->size(), 1u);
  EXPECT_EQ(audit->at(0).rpc, "migrate");
  EXPECT_NE(audit->at(0).detail.find("2 of 3 calibration versions converted"), std::string::npos) << audit->at(0).detail;

  for (int v = 1; v <= 2; ++v) {
    SCOPED_TRACE(v);
    auto row = (*store)->GetCalibration("IPM-OLD", v);
    ASSERT_TRUE(row.ok()) << row.status();
    EXPECT_TRUE(row->calibration_json.empty());
    EXPECT_LE(row->model_pb.size(), kMaxModelBytes);
    // The same calibration as the JSON read (which rounds the covariance).
    auto want = fit::Calibration::FromJson(nlohmann::json::parse(olds[v - 1].json));
    ASSERT_TRUE(want.ok());
    auto got = LoadCalibration(**store, "IPM-OLD", v);
    ASSERT_TRUE(got.ok()) << got.status();
    EXPECT_EQ(got->params(), want->params());
    EXPECT_EQ(got->covariance(), want->covariance());
    want->version = v;   // the stored JSON said 0; the row says v
    EXPECT_TRUE(EncodeCalibration(*got) == EncodeCalibration(*want)) << "read back differs";
    // The view (service replies, fluxcal query) is JSON.
    auto rec = GetCalibrationRecord(**store, "IPM-OLD", v);
    ASSERT_TRUE(rec.ok());
    want->version = 0;   // the view is the JSON as it was stored
    EXPECT_EQ(rec->calibration_json, want->ToJson().dump());
  }
  auto kept = (*store)->GetCalibration("IPM-OLD", 3);
  ASSERT_TRUE(kept.ok());
  EXPECT_EQ(kept->calibration_json, olds[2].json);
  EXPECT_TRUE(kept->model_pb.empty());

  // A new version is stored binary and chains on.
  storage::CalibrationRow next;
  next.serial = "IPM-OLD";
  next.model = "smooth";
  next.verdict = "pass";
  next.model_pb = EncodeCalibration(Fits().at("smooth"));
  ASSERT_TRUE((*store)->AddCalibration(next).ok());
  report = storage::VerifyChains(**store);
  ASSERT_TRUE(report.ok());
  EXPECT_TRUE(report->problems.empty()) << report->problems.front();
  EXPECT_EQ(report->chained, 4);

  // `fluxcal admin migrate` to the other backend carries the conversion
  // records along: the copy verifies as the source does.
  {
    std::string copy_url, copy_path;
    if (pg) {
      copy_path = (fs::temp_directory_path() / ("fluxcal_codec_copy_" + std::to_string(::getpid()) + ".db")).string();
      for (auto sfx : {"", "-wal", "-shm"}) fs::remove(copy_path + sfx);
      copy_url = copy_path;
    } else {
      cluster = fluxcal::testing::SharedPgCluster(&why);
      if (cluster != nullptr && cluster->CreateDatabase("codec_copy")) copy_url = cluster->Url("codec_copy");
    }
    if (!copy_url.empty()) {
      auto copy = OpenStore(copy_url);
      ASSERT_TRUE(copy.ok()) << copy.status();
      auto moved = Migrate(**store, **copy);
      ASSERT_TRUE(moved.ok()) << moved.status();
      auto copied = storage::VerifyChains(**copy);
      ASSERT_TRUE(copied.ok()) << copied.status();
      EXPECT_TRUE(copied->problems.empty()) << copied->problems.front();
      EXPECT_EQ(copied->converted, 2);
      EXPECT_EQ(copied->chained, 4);
      auto back = LoadCalibration(**copy, "IPM-OLD", 1);
      ASSERT_TRUE(back.ok()) << back.status();
      EXPECT_TRUE(EncodeCalibration(*back) == EncodeCalibration(*LoadCalibration(**store, "IPM-OLD", 1)));
    }
    if (!copy_path.empty()) {
      for (auto sfx : {"", "-wal", "-shm"}) fs::remove(copy_path + sfx);
    }
  }

  // The SQL that lets a row of table be edited: its trigger off (PostgreSQL)
  // or dropped (SQLite).
  auto allow_update = [&](const std::string& table, const std::string& trigger) {
    return raw(pg ? "ALTER TABLE " + table + " DISABLE TRIGGER " + trigger : "DROP TRIGGER " + trigger);
  };
  // A converted row edited behind the service is found.
  ASSERT_TRUE(allow_update("calibrations", "calibrations_no_update"));
  ASSERT_TRUE(raw(pg ? "UPDATE calibrations SET model_pb = model_pb || '\\x00'::bytea WHERE version = 1"
                     : "UPDATE calibrations SET model_pb = model_pb || x'00' WHERE version = 1"));
  report = storage::VerifyChains(**store);
  ASSERT_TRUE(report.ok());
  ASSERT_EQ(report->problems.size(), 1u);
  EXPECT_EQ(report->problems[0], "IPM-OLD v1: row changed after the v8 migration converted it to binary");
  EXPECT_EQ(storage::VerifyReleasedVersion(**store, "IPM-OLD", 1).code(), absl::StatusCode::kDataLoss);
  // So is an edited conversion record.
  ASSERT_TRUE(allow_update("calibration_conversions", "conversions_no_update"));
  ASSERT_TRUE(raw("UPDATE calibration_conversions SET json_sha256 = 'x' WHERE version = 2"));
  report = storage::VerifyChains(**store);
  ASSERT_TRUE(report.ok());
  ASSERT_EQ(report->problems.size(), 2u);
  EXPECT_EQ(report->problems[1], "IPM-OLD v2: row changed after the v8 migration converted it to binary");
  store->reset();
  if (!path.empty()) {
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(path + sfx);
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, MigrationTest, ::testing::Values(Backend::kSqlite, Backend::kPostgres),
                         [](const auto& info) { return info.param == Backend::kPostgres ? "Postgres" : "Sqlite"; });

}  // namespace
}  // namespace fluxcal::pipeline
