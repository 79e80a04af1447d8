// Each dialect as data (storage/dialect.h): its ordered migrations, index
// k bringing the schema from version k to k + 1, and the few clauses the
// shared SQL of storage/sql_store*.cc takes from it. Same tables, columns
// and order on both (docs/service.md); only types, identity columns and
// triggers are spelled each database's way. Compiled in every build (also
// without libpq): tests and tools read the PostgreSQL text without a server.
#include "storage/dialect.h"

#include "storage/store.h"

namespace fluxcal::storage {
namespace {

const std::vector<std::string> kSqliteMigrations = {
    // v1: motors, runs, points, recordings, calibrations.
    R"sql(
CREATE TABLE motors (
  serial TEXT PRIMARY KEY,
  pole_pairs INTEGER NOT NULL,
  rs_ohm REAL NOT NULL,
  psi_pm_wb REAL NOT NULL,
  created_utc TEXT NOT NULL);
CREATE TABLE recordings (
  sha256 TEXT PRIMARY KEY,
  size_bytes INTEGER NOT NULL,
  zlib_data BLOB NOT NULL);
CREATE TABLE runs (
  run_id INTEGER PRIMARY KEY AUTOINCREMENT,
  serial TEXT NOT NULL REFERENCES motors(serial),
  station TEXT NOT NULL,
  kind TEXT NOT NULL,
  recording_sha256 TEXT REFERENCES recordings(sha256),
  created_utc TEXT NOT NULL);
CREATE TABLE hf_points (
  run_id INTEGER NOT NULL REFERENCES runs(run_id),
  idx INTEGER NOT NULL,
  point_id TEXT NOT NULL,
  id_a REAL NOT NULL, iq_a REAL NOT NULL, speed_rpm REAL NOT NULL,
  ld_h REAL NOT NULL, lq_h REAL NOT NULL, ldq_h REAL,
  ld_h_std REAL NOT NULL, lq_h_std REAL NOT NULL, ldq_h_std REAL NOT NULL,
  temperature_c REAL NOT NULL, reliable INTEGER NOT NULL,
  PRIMARY KEY (run_id, idx));
CREATE TABLE calibrations (
  serial TEXT NOT NULL REFERENCES motors(serial),
  version INTEGER NOT NULL,
  run_id INTEGER REFERENCES runs(run_id),
  created_utc TEXT NOT NULL,
  model TEXT NOT NULL,
  psi_pm_wb REAL NOT NULL,
  rms_relative REAL NOT NULL,
  verdict TEXT NOT NULL,
  calibration_json TEXT NOT NULL,
  PRIMARY KEY (serial, version));
CREATE INDEX runs_by_serial ON runs(serial, run_id);
)sql",
    // v2: calibration versions are immutable, enforced by the database.
    R"sql(
CREATE TRIGGER calibrations_no_update BEFORE UPDATE ON calibrations
  BEGIN SELECT RAISE(ABORT, 'calibration versions are immutable'); END;
CREATE TRIGGER calibrations_no_delete BEFORE DELETE ON calibrations
  BEGIN SELECT RAISE(ABORT, 'calibration versions are immutable'); END;
CREATE INDEX calibrations_by_verdict ON calibrations(verdict);
)sql",
    // v3: idempotency keys on runs: a retried ingest with the same key
    // returns the first run instead of storing a second one.
    R"sql(
ALTER TABLE runs ADD COLUMN idempotency_key TEXT;
CREATE UNIQUE INDEX runs_idempotency ON runs(serial, idempotency_key) WHERE idempotency_key IS NOT NULL;
)sql",
    // v4: releases. A calibration becomes flashable only by an explicit,
    // recorded release; rows are insert-only like calibrations.
    R"sql(
CREATE TABLE releases (
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  released_by TEXT NOT NULL,
  released_utc TEXT NOT NULL,
  PRIMARY KEY (serial, version),
  FOREIGN KEY (serial, version) REFERENCES calibrations(serial, version));
CREATE TRIGGER releases_no_update BEFORE UPDATE ON releases
  BEGIN SELECT RAISE(ABORT, 'releases are immutable'); END;
CREATE TRIGGER releases_no_delete BEFORE DELETE ON releases
  BEGIN SELECT RAISE(ABORT, 'releases are immutable'); END;
)sql",
    // v5: audit trail: who (authenticated identity and role), from where
    // (peer), when, with which request id, did what to which serial.
    R"sql(
CREATE TABLE audit (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  utc TEXT NOT NULL,
  identity TEXT NOT NULL,
  role TEXT NOT NULL,
  peer TEXT NOT NULL,
  request_id TEXT NOT NULL,
  rpc TEXT NOT NULL,
  serial TEXT NOT NULL,
  detail TEXT NOT NULL);
CREATE INDEX audit_by_serial ON audit(serial, id);
CREATE TRIGGER audit_no_update BEFORE UPDATE ON audit
  BEGIN SELECT RAISE(ABORT, 'the audit trail is append-only'); END;
CREATE TRIGGER audit_no_delete BEFORE DELETE ON audit
  BEGIN SELECT RAISE(ABORT, 'the audit trail is append-only'); END;
)sql",
    // v6: a hash chain over calibration versions (storage/store.h,
    // CalibrationRowSha256): editing a stored row, even with the triggers
    // dropped, is detected by `fluxcal admin verify-db`.
    R"sql(
CREATE TABLE calibration_chain (
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  prev_sha256 TEXT NOT NULL,
  row_sha256 TEXT NOT NULL,
  PRIMARY KEY (serial, version));
CREATE TRIGGER chain_no_update BEFORE UPDATE ON calibration_chain
  BEGIN SELECT RAISE(ABORT, 'the calibration chain is append-only'); END;
CREATE TRIGGER chain_no_delete BEFORE DELETE ON calibration_chain
  BEGIN SELECT RAISE(ABORT, 'the calibration chain is append-only'); END;
)sql",
    // v7: a hash chain over releases, one for the whole store in release
    // order (storage/store.h, ReleaseRowSha256): a release inserted, changed
    // or removed behind the service is detected by `fluxcal admin
    // verify-db` and by a flasher's export. Releases stored before v7 are
    // linked by the migration itself (SqlStore::Migrate), in time order.
    R"sql(
CREATE TABLE release_chain (
  seq INTEGER PRIMARY KEY,
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  calibration_sha256 TEXT NOT NULL,
  prev_sha256 TEXT NOT NULL,
  row_sha256 TEXT NOT NULL,
  UNIQUE (serial, version));
CREATE TRIGGER release_chain_no_update BEFORE UPDATE ON release_chain
  BEGIN SELECT RAISE(ABORT, 'the release chain is append-only'); END;
CREATE TRIGGER release_chain_no_delete BEFORE DELETE ON release_chain
  BEGIN SELECT RAISE(ABORT, 'the release chain is append-only'); END;
)sql",
    // v8: calibration versions stored as the binary fitted model
    // (fluxcal.v1.CalibrationModel, ~45 kB for the largest family) instead
    // of decimal JSON (0.3-0.5 MB); calibration_json stays for versions
    // stored before and not converted ('' for the others). The migration
    // converts the versions already stored (SqlStore::Migrate,
    // ConvertStoredJson) and records each conversion: the JSON its chain
    // link hashed is gone, the record links the converted row to that link.
    R"sql(
ALTER TABLE calibrations ADD COLUMN model_pb BLOB;
CREATE TABLE calibration_conversions (
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  json_sha256 TEXT NOT NULL,
  row_sha256 TEXT NOT NULL,
  converted_utc TEXT NOT NULL,
  PRIMARY KEY (serial, version),
  FOREIGN KEY (serial, version) REFERENCES calibrations(serial, version));
CREATE TRIGGER conversions_no_update BEFORE UPDATE ON calibration_conversions
  BEGIN SELECT RAISE(ABORT, 'the conversion records are append-only'); END;
CREATE TRIGGER conversions_no_delete BEFORE DELETE ON calibration_conversions
  BEGIN SELECT RAISE(ABORT, 'the conversion records are append-only'); END;
)sql",
    // v9: each HF point's injection flux radius (HfPointRow::
    // hf_flux_radius_wb; NULL for points stored before or sent without).
    R"sql(
ALTER TABLE hf_points ADD COLUMN hf_flux_radius_wb REAL;
)sql",
};

// Same tables, columns and order as the SQLite migrations (docs/service.md);
// only the types are spelled the PostgreSQL way.
const std::vector<std::string> kPostgresMigrations = {
    // v1: motors, runs, points, recordings, calibrations.
    R"sql(
CREATE TABLE motors (
  serial TEXT PRIMARY KEY,
  pole_pairs INTEGER NOT NULL,
  rs_ohm DOUBLE PRECISION NOT NULL,
  psi_pm_wb DOUBLE PRECISION NOT NULL,
  created_utc TEXT NOT NULL);
CREATE TABLE recordings (
  sha256 TEXT PRIMARY KEY,
  size_bytes BIGINT NOT NULL,
  zlib_data BYTEA NOT NULL);
CREATE TABLE runs (
  run_id BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY,
  serial TEXT NOT NULL REFERENCES motors(serial),
  station TEXT NOT NULL,
  kind TEXT NOT NULL,
  recording_sha256 TEXT REFERENCES recordings(sha256),
  created_utc TEXT NOT NULL);
CREATE TABLE hf_points (
  run_id BIGINT NOT NULL REFERENCES runs(run_id),
  idx INTEGER NOT NULL,
  point_id TEXT NOT NULL,
  id_a DOUBLE PRECISION NOT NULL, iq_a DOUBLE PRECISION NOT NULL, speed_rpm DOUBLE PRECISION NOT NULL,
  ld_h DOUBLE PRECISION NOT NULL, lq_h DOUBLE PRECISION NOT NULL, ldq_h DOUBLE PRECISION,
  ld_h_std DOUBLE PRECISION NOT NULL, lq_h_std DOUBLE PRECISION NOT NULL, ldq_h_std DOUBLE PRECISION NOT NULL,
  temperature_c DOUBLE PRECISION NOT NULL, reliable INTEGER NOT NULL,
  PRIMARY KEY (run_id, idx));
CREATE TABLE calibrations (
  serial TEXT NOT NULL REFERENCES motors(serial),
  version INTEGER NOT NULL,
  run_id BIGINT REFERENCES runs(run_id),
  created_utc TEXT NOT NULL,
  model TEXT NOT NULL,
  psi_pm_wb DOUBLE PRECISION NOT NULL,
  rms_relative DOUBLE PRECISION NOT NULL,
  verdict TEXT NOT NULL,
  calibration_json TEXT NOT NULL,
  PRIMARY KEY (serial, version));
CREATE INDEX runs_by_serial ON runs(serial, run_id);
)sql",
    // v2: calibration versions are immutable, enforced by the database.
    R"sql(
CREATE FUNCTION fluxcal_calibrations_immutable() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN RAISE EXCEPTION 'calibration versions are immutable'; END $$;
CREATE TRIGGER calibrations_no_update BEFORE UPDATE OR DELETE ON calibrations
  FOR EACH ROW EXECUTE FUNCTION fluxcal_calibrations_immutable();
CREATE TRIGGER calibrations_no_truncate BEFORE TRUNCATE ON calibrations
  FOR EACH STATEMENT EXECUTE FUNCTION fluxcal_calibrations_immutable();
CREATE INDEX calibrations_by_verdict ON calibrations(verdict);
)sql",
    // v3: idempotency keys on runs: a retried ingest with the same key
    // returns the first run instead of storing a second one.
    R"sql(
ALTER TABLE runs ADD COLUMN idempotency_key TEXT;
CREATE UNIQUE INDEX runs_idempotency ON runs(serial, idempotency_key) WHERE idempotency_key IS NOT NULL;
)sql",
    // v4: releases. A calibration becomes flashable only by an explicit,
    // recorded release; rows are insert-only like calibrations.
    R"sql(
CREATE TABLE releases (
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  released_by TEXT NOT NULL,
  released_utc TEXT NOT NULL,
  PRIMARY KEY (serial, version),
  FOREIGN KEY (serial, version) REFERENCES calibrations(serial, version));
CREATE FUNCTION releases_immutable() RETURNS trigger LANGUAGE plpgsql AS $$
  BEGIN RAISE EXCEPTION 'releases are immutable'; END $$;
CREATE TRIGGER releases_no_update BEFORE UPDATE OR DELETE ON releases
  FOR EACH ROW EXECUTE FUNCTION releases_immutable();
CREATE TRIGGER releases_no_truncate BEFORE TRUNCATE ON releases
  FOR EACH STATEMENT EXECUTE FUNCTION releases_immutable();
)sql",
    // v5: audit trail: who (authenticated identity and role), from where
    // (peer), when, with which request id, did what to which serial.
    R"sql(
CREATE TABLE audit (
  id BIGSERIAL PRIMARY KEY,
  utc TEXT NOT NULL,
  identity TEXT NOT NULL,
  role TEXT NOT NULL,
  peer TEXT NOT NULL,
  request_id TEXT NOT NULL,
  rpc TEXT NOT NULL,
  serial TEXT NOT NULL,
  detail TEXT NOT NULL);
CREATE INDEX audit_by_serial ON audit(serial, id);
CREATE FUNCTION audit_append_only() RETURNS trigger LANGUAGE plpgsql AS $$
  BEGIN RAISE EXCEPTION 'the audit trail is append-only'; END $$;
CREATE TRIGGER audit_no_update BEFORE UPDATE OR DELETE ON audit
  FOR EACH ROW EXECUTE FUNCTION audit_append_only();
CREATE TRIGGER audit_no_truncate BEFORE TRUNCATE ON audit
  FOR EACH STATEMENT EXECUTE FUNCTION audit_append_only();
)sql",
    // v6: a hash chain over calibration versions (storage/store.h,
    // CalibrationRowSha256): editing a stored row, even with the triggers
    // dropped, is detected by `fluxcal admin verify-db`.
    R"sql(
CREATE TABLE calibration_chain (
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  prev_sha256 TEXT NOT NULL,
  row_sha256 TEXT NOT NULL,
  PRIMARY KEY (serial, version));
CREATE TRIGGER chain_no_update BEFORE UPDATE OR DELETE ON calibration_chain
  FOR EACH ROW EXECUTE FUNCTION audit_append_only();
)sql",
    // v7: a hash chain over releases, one for the whole store in release
    // order (storage/store.h, ReleaseRowSha256): a release inserted, changed
    // or removed behind the service is detected by `fluxcal admin
    // verify-db` and by a flasher's export. Releases stored before v7 are
    // linked by the migration itself (SqlStore::Migrate), in time
    // order. Both chains also refuse TRUNCATE.
    R"sql(
CREATE TABLE release_chain (
  seq BIGINT PRIMARY KEY,
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  calibration_sha256 TEXT NOT NULL,
  prev_sha256 TEXT NOT NULL,
  row_sha256 TEXT NOT NULL,
  UNIQUE (serial, version));
CREATE FUNCTION fluxcal_chain_append_only() RETURNS trigger LANGUAGE plpgsql AS $$
  BEGIN RAISE EXCEPTION 'hash chains are append-only'; END $$;
CREATE TRIGGER release_chain_no_update BEFORE UPDATE OR DELETE ON release_chain
  FOR EACH ROW EXECUTE FUNCTION fluxcal_chain_append_only();
CREATE TRIGGER release_chain_no_truncate BEFORE TRUNCATE ON release_chain
  FOR EACH STATEMENT EXECUTE FUNCTION fluxcal_chain_append_only();
CREATE TRIGGER chain_no_truncate BEFORE TRUNCATE ON calibration_chain
  FOR EACH STATEMENT EXECUTE FUNCTION fluxcal_chain_append_only();
)sql",
    // v8: calibration versions stored as the binary fitted model
    // (fluxcal.v1.CalibrationModel) instead of decimal JSON; the versions
    // already stored are converted by the migration itself
    // (SqlStore::Migrate, ConvertStoredJson), each with its record.
    // model_pb is stored as is (STORAGE EXTERNAL: the binary does not
    // compress, so TOAST need not try).
    R"sql(
ALTER TABLE calibrations ADD COLUMN model_pb BYTEA;
ALTER TABLE calibrations ALTER COLUMN model_pb SET STORAGE EXTERNAL;
CREATE TABLE calibration_conversions (
  serial TEXT NOT NULL,
  version INTEGER NOT NULL,
  json_sha256 TEXT NOT NULL,
  row_sha256 TEXT NOT NULL,
  converted_utc TEXT NOT NULL,
  PRIMARY KEY (serial, version),
  FOREIGN KEY (serial, version) REFERENCES calibrations(serial, version));
CREATE TRIGGER conversions_no_update BEFORE UPDATE OR DELETE ON calibration_conversions
  FOR EACH ROW EXECUTE FUNCTION fluxcal_chain_append_only();
CREATE TRIGGER conversions_no_truncate BEFORE TRUNCATE ON calibration_conversions
  FOR EACH STATEMENT EXECUTE FUNCTION fluxcal_chain_append_only();
)sql",
    // v9: each HF point's injection flux radius.
    R"sql(
ALTER TABLE hf_points ADD COLUMN hf_flux_radius_wb DOUBLE PRECISION;
)sql",
};

}  // namespace

const Dialect& SqliteDialect() {
  static const Dialect d{
      .name = "sqlite",
      .migrations = kSqliteMigrations,
      .begin = "BEGIN IMMEDIATE",
      .for_update = "",
      .for_share = "",
      .bytewise = "",
      .advisory_lock = "",
      .table_exists = "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = ?",
      // SQLite cannot disable a trigger: it is dropped and created again,
      // inside the migration's transaction.
      .unlock_calibrations = "DROP TRIGGER calibrations_no_update",
      .relock_calibrations = "CREATE TRIGGER calibrations_no_update BEFORE UPDATE ON calibrations "
                             "BEGIN SELECT RAISE(ABORT, 'calibration versions are immutable'); END;",
      // AUTOINCREMENT continues after the largest id inserted.
      .after_import_runs = "",
      .after_import_audit = "",
  };
  return d;
}

const Dialect& PostgresDialect() {
  static const Dialect d{
      .name = "postgresql",
      .migrations = kPostgresMigrations,
      .begin = "BEGIN",
      .for_update = " FOR UPDATE",
      .for_share = " FOR SHARE",
      .bytewise = " COLLATE \"C\"",
      .advisory_lock = "SELECT pg_advisory_xact_lock(?)",
      .table_exists = "SELECT CASE WHEN to_regclass(?) IS NULL THEN 0 ELSE 1 END",
      .unlock_calibrations = "ALTER TABLE calibrations DISABLE TRIGGER calibrations_no_update",
      .relock_calibrations = "ALTER TABLE calibrations ENABLE TRIGGER calibrations_no_update",
      .after_import_runs = "SELECT setval(pg_get_serial_sequence('runs', 'run_id'), (SELECT MAX(run_id) FROM runs))",
      .after_import_audit = "SELECT setval(pg_get_serial_sequence('audit', 'id'), (SELECT MAX(id) FROM audit))",
  };
  return d;
}

const std::vector<std::string>& SqliteMigrations() { return SqliteDialect().migrations; }
const std::vector<std::string>& PostgresMigrations() { return PostgresDialect().migrations; }

}  // namespace fluxcal::storage
