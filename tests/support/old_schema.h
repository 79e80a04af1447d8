// A store as an older fluxcal left it, for the migration tests: the schema
// of migrations 1..N, each recorded in schema_version, and one motor.
#ifndef FLUXCAL_TESTS_SUPPORT_OLD_SCHEMA_H_
#define FLUXCAL_TESTS_SUPPORT_OLD_SCHEMA_H_

#include <functional>
#include <string>
#include <vector>

#include "gtest/gtest.h"

namespace fluxcal::testing {

// Runs migrations[0..version) through raw (one SQL text a call, true when
// it ran) with schema_version rows as the store writes them, then adds
// the motor IPM-OLD (4 pole pairs, 0.011 ohm, 0.0114 Wb).
inline ::testing::AssertionResult OldSchemaWithMotor(const std::function<bool(const std::string&)>& raw,
                                                     const std::vector<std::string>& migrations, int version) {
  if (!raw("CREATE TABLE schema_version (version INTEGER NOT NULL)")) {
    return ::testing::AssertionFailure() << "schema_version";
  }
  for (int v = 0; v < version; ++v) {
    if (!raw(migrations[v])) return ::testing::AssertionFailure() << "migration " << v + 1;
    if (!raw("INSERT INTO schema_version (version) VALUES (" + std::to_string(v + 1) + ")")) {
      return ::testing::AssertionFailure() << "schema_version " << v + 1;
    }
  }
  if (!raw("INSERT INTO motors (serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc) "
           "VALUES ('IPM-OLD', 4, 0.011, 0.0114, '2024-01-01T00:00:00Z')")) {
    return ::testing::AssertionFailure() << "motor IPM-OLD";
  }
  return ::testing::AssertionSuccess();
}

}  // namespace fluxcal::testing

#endif  // FLUXCAL_TESTS_SUPPORT_OLD_SCHEMA_H_
