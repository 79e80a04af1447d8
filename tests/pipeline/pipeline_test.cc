// The use cases over the storage interface: ingest rules, fit and verdict
// against the twin's known motor, query accuracy, diagnosis of a stored
// recording, and moving a store (migrate SQLite -> PostgreSQL, backup,
// content hashes) including through the `fluxcal admin` command.
#include "pipeline/pipeline.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "io/sha256.h"
#include "nlohmann/json.hpp"
#include "pipeline/anchor.h"
#include "pipeline/facts.h"
#include "pipeline/ingest_stream.h"
#include "pipeline/report.h"
#include "simulation/trait_motor.h"
#include "simulation/twin.h"
#include "storage/sqlite.h"
#include "tests/support/pg_cluster.h"

namespace fluxcal::pipeline {
namespace {

namespace fs = std::filesystem;

std::string Temp(const std::string& name) {
  return (fs::temp_directory_path() / ("fluxcal_pipe_" + std::to_string(::getpid()) + "_" + name)).string();
}

void RemoveDb(const std::string& p) {
  for (auto sfx : {"", "-wal", "-shm"}) fs::remove(p + sfx);
}

// 36 identified points of the twin's analytic motor, scaled.
std::vector<IdentifiedPoint> Grid(double scale) {
  sim::AnalyticMotor m{sim::MotorParams{}};
  std::vector<IdentifiedPoint> out;
  for (int a = 0; a < 6; ++a) {
    for (int b = 0; b < 6; ++b) {
      IdentifiedPoint p;
      p.point_id = "p" + std::to_string(6 * a + b);
      p.id_a = -100 + 20 * a;
      p.iq_a = 20 * b;
      const auto L = m.Inductance(p.id_a, p.iq_a);
      p.ld_h = scale * L.ldd_h; p.lq_h = scale * L.lqq_h; p.ldq_h = L.ldq_h;
      p.ld_h_std = p.lq_h_std = p.ldq_h_std = 1e-7;
      out.push_back(p);
    }
  }
  return out;
}

const MotorNominal kMotor{4, 0.011, 0.0114};

// A store in memory holding serial's run of Grid(1.0) (kMotor) and its
// analytic fit, version 1.
absl::StatusOr<std::unique_ptr<storage::Store>> StoreWithAnalyticFit(const std::string& serial) {
  auto store = storage::Store::Open(":memory:");
  if (!store.ok()) return store.status();
  if (auto run = IngestHfRun(**store, serial, "st", kMotor, Grid(1.0)); !run.ok()) return run.status();
  if (auto row = FitSerial(**store, serial, "analytic", {}); !row.ok()) return row.status();
  return store;
}

// StoreWithAnalyticFit's store and its version 1, loaded.
struct FittedStore {
  std::unique_ptr<storage::Store> store;
  fit::Calibration cal;
};

// Fills *out for `serial`; fatal failures when either step fails (callers
// wrap the call in ASSERT_NO_FATAL_FAILURE).
void FitAndLoad(const std::string& serial, FittedStore* out) {
  auto store = StoreWithAnalyticFit(serial);
  ASSERT_TRUE(store.ok()) << store.status();
  auto cal = LoadCalibration(**store, serial, 1);
  ASSERT_TRUE(cal.ok()) << cal.status();
  out->store = std::move(*store);
  out->cal = std::move(*cal);
}

// `cal` with a measured region that holds no current circle (measured id
// only >= 0): no current limit to take from it.
fit::Calibration WithoutCurrentCircle(const fit::Calibration& cal) {
  return fit::Calibration(cal.serial(), cal.family(), cal.params(), cal.covariance(), cal.pole_pairs(), cal.rs_ohm(),
                          0.0, 20.0, 0.0, 100.0);
}

// Stores `cal` as a new version of `serial` (run 1) with a failed verdict;
// the version, as AddCalibration returns it.
absl::StatusOr<int> AddFailedCalibration(storage::Store& store, const std::string& serial,
                                         const fit::Calibration& cal) {
  storage::CalibrationRow row;
  row.serial = serial;
  row.run_id = 1;
  row.model = cal.family().Name();
  row.verdict = "fail: test";
  row.calibration_json = cal.ToJson().dump();
  return store.AddCalibration(row);
}

// A table of `points` rows over `speed_points` speeds.
tables::TableSpec GridSpec(int points, int speed_points) {
  tables::TableSpec spec;
  spec.points = points;
  spec.speed_points = speed_points;
  return spec;
}

TEST(Pipeline, IngestRules) {
  auto store = storage::Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  auto r = IngestHfRun(**store, "IPM-N", "st", std::nullopt, Grid(1));
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("motor: required"), std::string::npos);
  r = IngestHfRun(**store, "IPM-N", "st", kMotor, {}, 3);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("(3 rejected)"), std::string::npos);
  ASSERT_TRUE(IngestHfRun(**store, "IPM-N", "st", kMotor, Grid(1)).ok());
  // Known serial: the motor may be left out.
  EXPECT_TRUE(IngestHfRun(**store, "IPM-N", "st", std::nullopt, Grid(1)).ok());
  EXPECT_EQ((*store)->GetMotor("IPM-N")->psi_pm_wb, 0.0114);
}

// A cancellation callback (a server passes its client's deadline) stops the
// fit inside its loop over candidate models, and nothing is stored.
TEST(Pipeline, CancelledFitStoresNothing) {
  auto store = storage::Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(IngestHfRun(**store, "IPM-C", "st", kMotor, Grid(1.0)).ok());
  int polls = 0;
  auto row = FitSerial(**store, "IPM-C", "auto", {}, nullptr, [&polls] { return ++polls > 2; });
  EXPECT_EQ(row.status().code(), absl::StatusCode::kCancelled) << row.status();
  EXPECT_EQ(polls, 3) << "polled per candidate model, stopped at the third";
  EXPECT_EQ((*store)->GetCalibration("IPM-C", 0).status().code(), absl::StatusCode::kNotFound);
  storage::AuditContext audit;
  audit.row.rpc = "Fit";
  audit.row.serial = "IPM-C";
  row = FitSerial(**store, "IPM-C", "analytic", {}, &audit, [] { return true; });
  EXPECT_EQ(row.status().code(), absl::StatusCode::kCancelled);
  EXPECT_TRUE((*store)->AuditOf("IPM-C")->empty()) << "no audit row for a write that did not happen";
  row = FitSerial(**store, "IPM-C", "analytic", {}, &audit, [] { return false; });
  ASSERT_TRUE(row.ok()) << row.status();
  EXPECT_EQ(row->version, 1);
  ASSERT_EQ((*store)->AuditOf("IPM-C")->size(), 1u);
  EXPECT_EQ((*store)->AuditOf("IPM-C")->at(0).detail, "version 1 (analytic): pass");
}

// The parsed-calibration cache (LoadCalibration) never serves one store's
// or one version's calibration for another: two stores with the same
// serial but different data, and a new version, each read back their own.
TEST(Pipeline, CachedCalibrationsAreTheStoredOnes) {
  auto a = storage::Store::Open(":memory:");
  auto b = storage::Store::Open(":memory:");
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_TRUE(IngestHfRun(**a, "IPM-K", "st", kMotor, Grid(1.0)).ok());
  ASSERT_TRUE(IngestHfRun(**b, "IPM-K", "st", kMotor, Grid(1.1)).ok());
  ASSERT_TRUE(FitSerial(**a, "IPM-K", "analytic", {}).ok());
  ASSERT_TRUE(FitSerial(**b, "IPM-K", "analytic", {}).ok());
  for (int round = 0; round < 2; ++round) {   // second round: cache hits
    auto ca = LoadCalibration(**a, "IPM-K", 0), cb = LoadCalibration(**b, "IPM-K", 0);
    ASSERT_TRUE(ca.ok() && cb.ok());
    EXPECT_NEAR(cb->Inductance(-20, 40).lqq_h / ca->Inductance(-20, 40).lqq_h, 1.1, 0.01) << round;
  }
  ASSERT_TRUE(IngestHfRun(**a, "IPM-K", "st", std::nullopt, Grid(1.2)).ok());
  ASSERT_TRUE(FitSerial(**a, "IPM-K", "analytic", {}).ok());
  auto latest = LoadCalibration(**a, "IPM-K", 0), first = LoadCalibration(**a, "IPM-K", 1);
  ASSERT_TRUE(latest.ok() && first.ok());
  EXPECT_EQ(latest->version, 2);
  EXPECT_EQ(first->version, 1);
  EXPECT_NEAR(latest->Inductance(-20, 40).lqq_h / first->Inductance(-20, 40).lqq_h, 1.2, 0.01);
}

TEST(Pipeline, FitJudgeQueryExport) {
  auto store = storage::Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(IngestHfRun(**store, "IPM-F", "st", kMotor, Grid(1.02)).ok());
  auto row = FitSerial(**store, "IPM-F", "analytic", {});
  ASSERT_TRUE(row.ok()) << row.status();
  EXPECT_EQ(row->version, 1);
  EXPECT_EQ(row->verdict, "pass");
  // Points that scatter 8 % fail the motor, naming the reason; the version
  // still counts (a refit is n+1, the failed one stays on record).
  auto noisy = Grid(1.0);
  for (size_t k = 0; k < noisy.size(); ++k) noisy[k].lq_h *= k % 2 ? 1.08 : 0.92;
  ASSERT_TRUE(IngestHfRun(**store, "IPM-F", "st", std::nullopt, noisy).ok());
  auto bad = FitSerial(**store, "IPM-F", "analytic", {});
  ASSERT_TRUE(bad.ok());
  EXPECT_EQ(bad->version, 2);
  EXPECT_EQ(bad->verdict.rfind("fail: fit residual", 0), 0u) << bad->verdict;
  auto q = QueryFlux(**store, "IPM-F", 1, {{-40, 60}, {-20, 40}});
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->version, 1);
  sim::AnalyticMotor truth{sim::MotorParams{}};
  EXPECT_NEAR(q->values[0].ldd_h / (1.02 * truth.Inductance(-40, 60).ldd_h), 1.0, 0.005);
  EXPECT_NEAR(q->values[1].lqq_h / (1.02 * truth.Inductance(-20, 40).lqq_h), 1.0, 0.005);
  tables::TableSpec spec;
  spec.points = 16;
  auto e = ExportTable(**store, "IPM-F", 0, spec, tables::ExportRequest{}, "csv");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->version, 2);
  EXPECT_EQ(e->exported.payload_sha256.size(), 64u);
  // Verdict and release state of the stored version travel inside the file.
  EXPECT_FALSE(e->verdict.empty());
  EXPECT_NE(e->exported.bytes.find("# verdict: " + e->verdict + "\n"), std::string::npos) << e->exported.bytes.substr(0, 800);
  EXPECT_NE(e->exported.bytes.find("# release_state: not released\n"), std::string::npos);
  EXPECT_NE(e->exported.bytes.find("# serial: IPM-F\n"), std::string::npos);
  EXPECT_EQ(QueryFlux(**store, "NOPE", 0, {{0, 0}}).status().code(), absl::StatusCode::kNotFound);
}

// The service's export under the one export rule (tables/export_rule.h):
// a run of HF results stores no DC-link voltage, so a field-weakening or
// MTPV table needs udc_v in the request (before: 50 V, silently); a mostly
// clamped table is FAILED_PRECONDITION unless allow_clamped; a calibration
// without a measured current circle needs i_max_a (before: 150 A).
TEST(Pipeline, ExportTakesTheCalibrationsFactsOrTheRequests) {
  auto store = StoreWithAnalyticFit("IPM-X");
  ASSERT_TRUE(store.ok()) << store.status();
  tables::ExportRequest rpc;
  rpc.names_flags = false;
  tables::TableSpec spec;
  spec.points = 9;
  spec.speed_points = 8;
  for (const char* kind : {"fw", "mtpv"}) {
    spec.kind = kind;
    auto e = ExportTable(**store, "IPM-X", 0, spec, rpc, "csv");
    ASSERT_EQ(e.status().code(), absl::StatusCode::kInvalidArgument) << kind << ": " << e.status();
    EXPECT_EQ(e.status().message().rfind("udc_v: ", 0), 0u) << e.status();
  }
  spec.kind = "fw";
  rpc.udc_v = 50;
  auto e = ExportTable(**store, "IPM-X", 0, spec, rpc, "csv");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_GT(e->cells, 0);
  EXPECT_LE(e->cells, 9 * 8) << "at most --points x --speed-points cells";
  EXPECT_NE(e->exported.bytes.find("# udc_v: 50 V"), std::string::npos);
  EXPECT_EQ(e->limits.udc_source, "udc_v");
  EXPECT_LE(e->clamped_cells * 2, e->cells);
  rpc.udc_v = 8;
  auto clamped = ExportTable(**store, "IPM-X", 0, spec, rpc, "csv");
  ASSERT_EQ(clamped.status().code(), absl::StatusCode::kFailedPrecondition) << clamped.status();
  EXPECT_NE(clamped.status().message().find("give allow_clamped"), std::string::npos) << clamped.status();
  rpc.allow_clamped = true;
  clamped = ExportTable(**store, "IPM-X", 0, spec, rpc, "csv");
  ASSERT_TRUE(clamped.ok()) << clamped.status();
  EXPECT_GT(clamped->clamped_cells * 2, clamped->cells);

  // A stored calibration whose measured region holds no current circle.
  auto cal = LoadCalibration(**store, "IPM-X", 1);
  ASSERT_TRUE(cal.ok());
  const fit::Calibration no_circle = WithoutCurrentCircle(*cal);
  ASSERT_TRUE(AddFailedCalibration(**store, "IPM-X", no_circle).ok());
  spec.kind = "mtpa";
  rpc = tables::ExportRequest{};
  rpc.names_flags = false;
  auto i_max = ExportTable(**store, "IPM-X", 2, spec, rpc, "csv");
  ASSERT_EQ(i_max.status().code(), absl::StatusCode::kInvalidArgument) << i_max.status();
  EXPECT_EQ(i_max.status().message().rfind("i_max_a: ", 0), 0u) << i_max.status();
}

// `fluxcal export cal.json` and the service's ExportTable are one path
// (pipeline/export.h): for the same calibration and request they compute
// the same cells from the same limits, and differ only in what the store
// adds (verdict, release state). Where the two copies once disagreed, a
// calibration without a measured current circle, both refuse and name the
// input to give (the CLI's behaviour, documented in docs/tables.md); the
// service used to export it at 150 A.
// A Udc axis (docs/tables.md, "Tables over Udc"): each file of the axis
// carries the single export's values at its voltage (the same payload),
// under labels tagged with it, and the envelope goes through the stored
// path as the local one.
TEST(Pipeline, UdcAxisExportsAreTheSingleExportsPerUdc) {
  FittedStore fitted;
  ASSERT_NO_FATAL_FAILURE(FitAndLoad("IPM-U", &fitted));
  tables::TableSpec spec = GridSpec(12, 8);
  tables::ExportRequest req;
  req.rs_ohm = 0.011;
  req.allow_clamped = true;
  for (const char* kind : {"fw", "envelope"}) {
    spec.kind = kind;
    auto axis = ExportCalibrationOverUdc(fitted.cal, spec, req, {40, 60}, "dcm");
    ASSERT_TRUE(axis.ok()) << kind << ": " << axis.status();
    ASSERT_EQ(axis->size(), 2u);
    for (const auto& a : *axis) {
      tables::ExportRequest one = req;
      one.udc_v = a.udc_v;
      auto single = ExportCalibration(fitted.cal, spec, one, "dcm");
      ASSERT_TRUE(single.ok()) << single.status();
      EXPECT_EQ(a.result.exported.payload_sha256, single->exported.payload_sha256) << kind << " at " << a.udc_v;
      EXPECT_EQ(a.result.table.outputs[0].values, single->table.outputs[0].values);
      const std::string label = absl::StrFormat("FLUXCAL_%s_UDC%gV_ID_A", absl::AsciiStrToUpper(kind), a.udc_v);
      EXPECT_NE(a.result.exported.bytes.find(label), std::string::npos) << label;
    }
    tables::ExportRequest rpc = req;
    rpc.names_flags = false;
    rpc.udc_v = 60;
    auto stored = ExportTable(*fitted.store, "IPM-U", 1, spec, rpc, "csv");
    ASSERT_TRUE(stored.ok()) << stored.status();
    EXPECT_EQ(stored->exported.payload_sha256, (*axis)[1].result.exported.payload_sha256) << kind;
  }
  EXPECT_EQ(UdcAxisPath("out/fw.h", 300), "out/fw_udc300v.h");
  EXPECT_EQ(UdcAxisPath("out.d/fw", 312.5), "out.d/fw_udc312p5v");
  EXPECT_EQ(UdcAxisPath(".fw", 48), ".fw_udc48v");
}

// A file's bytes without the lines that name the moment it was written.
std::string WithoutCreatedUtc(const std::string& bytes) {
  std::string out;
  size_t at = 0;
  while (at < bytes.size()) {
    size_t end = bytes.find('\n', at);
    end = end == std::string::npos ? bytes.size() : end + 1;
    const std::string line = bytes.substr(at, end - at);
    if (line.find("created_utc") == std::string::npos) out += line;
    at = end;
  }
  return out;
}

// The service's Udc axis (ExportTable udc_axis_v): the stored version's
// tables, one per voltage, each the single stored export at that voltage
// (the same file but for its tagged labels and the time it was written),
// with the stored verdict and release state, and file names as the CLI
// gives them; the generating envelope through the same path.
TEST(Pipeline, StoredUdcAxisIsTheStoredSingleExportPerUdc) {
  auto store = StoreWithAnalyticFit("IPM-V");
  ASSERT_TRUE(store.ok()) << store.status();
  tables::TableSpec spec;
  spec.points = 12;
  spec.speed_points = 8;
  tables::ExportRequest rpc;
  rpc.names_flags = false;
  rpc.rs_ohm = 0.011;
  rpc.allow_clamped = true;
  for (const char* kind : {"fw", "envelope", "mtpa"}) {
    for (const bool generating : {false, true}) {
      if (generating && std::string(kind) != "envelope") continue;
      SCOPED_TRACE(std::string(kind) + (generating ? " generating" : ""));
      spec.kind = kind;
      spec.envelope_generating = generating;
      auto axis = ExportTableOverUdc(**store, "IPM-V", 0, spec, rpc, {40, 60, 80}, "csv");
      ASSERT_TRUE(axis.ok()) << axis.status();
      EXPECT_EQ(axis->version, 1);
      EXPECT_FALSE(axis->verdict.empty());
      EXPECT_FALSE(axis->released);
      ASSERT_EQ(axis->tables.size(), 3u);
      for (const auto& a : axis->tables) {
        tables::ExportRequest one = rpc;
        one.udc_v = a.udc_v;
        auto single = ExportTable(**store, "IPM-V", 0, spec, one, "csv");
        ASSERT_TRUE(single.ok()) << single.status();
        EXPECT_EQ(a.result.exported.payload_sha256, single->exported.payload_sha256) << a.udc_v;
        // CSV names no labels: the same bytes.
        EXPECT_EQ(WithoutCreatedUtc(a.result.exported.bytes), WithoutCreatedUtc(single->exported.bytes)) << a.udc_v;
        EXPECT_EQ(a.result.verdict, axis->verdict);
        EXPECT_NE(a.result.exported.bytes.find("# verdict: " + axis->verdict + "\n"), std::string::npos);
      }
      EXPECT_EQ(ExportFileName("IPM-V", spec, "csv", 60),
                absl::StrCat("IPM-V_", kind, generating ? "_generating" : "", "_udc60v.csv"));
    }
  }
  // The generating envelope is the table the report page draws
  // (tables::BuildTable with envelope_generating under the export rule's
  // limits), bit for bit, torque <= 0, at standstill the motoring limit's
  // magnitude (the fitted model is symmetric in iq).
  spec.kind = "envelope";
  spec.speed_points = 16;
  spec.speed_max_rpm = 4000;
  tables::ExportRequest at60 = rpc;
  at60.udc_v = 60;
  spec.envelope_generating = false;
  auto mot = ExportTable(**store, "IPM-V", 0, spec, at60, "dcm");
  spec.envelope_generating = true;
  auto gen = ExportTable(**store, "IPM-V", 0, spec, at60, "dcm");
  ASSERT_TRUE(mot.ok() && gen.ok()) << mot.status() << gen.status();
  auto cal = LoadCalibration(**store, "IPM-V", 1);
  ASSERT_TRUE(cal.ok());
  tables::TableSpec page = spec;
  page.measured_current_limit_a = cal->MeasuredCurrentLimitA();
  auto drawn = tables::BuildTable(*cal, gen->limits.limits, page);
  ASSERT_TRUE(drawn.ok()) << drawn.status();
  ASSERT_EQ(drawn->outputs[2].name, "torque_nm");
  EXPECT_EQ(gen->table.outputs[2].values, drawn->outputs[2].values);
  const auto& tg = gen->table.outputs[2].values;
  const auto& tm = mot->table.outputs[2].values;
  for (double t : tg) EXPECT_LE(t, 0.0);
  EXPECT_NEAR(-tg[0], tm[0], 1e-9 * tm[0]);
  EXPECT_NE(gen->exported.bytes.find("KENNLINIE FLUXCAL_ENVELOPE_GENERATING_TORQUE_NM "), std::string::npos);
  EXPECT_NE(mot->exported.bytes.find("KENNLINIE FLUXCAL_ENVELOPE_TORQUE_NM "), std::string::npos);
  // Refused before the store is read: with another table, and an axis
  // with a Udc.
  spec.kind = "fw";
  auto bad = ExportTable(**store, "IPM-NONE", 0, spec, rpc, "csv");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.status().message().rfind("generating: ", 0), 0u) << bad.status();
  spec.kind = "envelope";
  auto both = ExportTableOverUdc(**store, "IPM-V", 0, spec, at60, {40, 60}, "csv");
  ASSERT_FALSE(both.ok());
  EXPECT_EQ(both.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(both.status().message().find("udc_axis_v"), std::string::npos) << both.status();
}

TEST(Pipeline, LocalAndStoredExportsAreOnePath) {
  FittedStore fitted;
  ASSERT_NO_FATAL_FAILURE(FitAndLoad("IPM-L", &fitted));
  tables::TableSpec spec = GridSpec(12, 6);
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    spec.kind = kind;
    tables::ExportRequest flags;   // as `fluxcal export` states it
    flags.udc_v = 60;
    tables::ExportRequest rpc = flags;   // as the RPC states it
    rpc.names_flags = false;
    auto local = ExportCalibration(fitted.cal, spec, flags, "csv");
    auto stored = ExportTable(*fitted.store, "IPM-L", 1, spec, rpc, "csv");
    ASSERT_TRUE(local.ok()) << kind << ": " << local.status();
    ASSERT_TRUE(stored.ok()) << kind << ": " << stored.status();
    EXPECT_EQ(local->exported.payload_sha256, stored->exported.payload_sha256) << kind;
    EXPECT_EQ(local->cells, stored->cells) << kind;
    EXPECT_EQ(local->clamped_cells, stored->clamped_cells) << kind;
    EXPECT_EQ(local->extrapolated_cells, stored->extrapolated_cells) << kind;
    EXPECT_EQ(local->limits.limits.i_max_a, stored->limits.limits.i_max_a) << kind;
    EXPECT_EQ(local->limits.limits.udc_v, stored->limits.limits.udc_v) << kind;
    EXPECT_EQ(local->version, 1);
    // A file alone says it does not know; the store says what it knows.
    EXPECT_NE(local->exported.bytes.find(std::string("# release_state: ") + tables::kReleaseUnknown + "\n"),
              std::string::npos);
    EXPECT_NE(stored->exported.bytes.find("# release_state: not released\n"), std::string::npos);
    EXPECT_NE(stored->exported.bytes.find("# verdict: " + stored->verdict + "\n"), std::string::npos);
    // The figure of `fluxcal export --svg` comes from the same result.
    EXPECT_NE(ExportFigureSvg(fitted.cal, spec, *local).find("<svg"), std::string::npos) << kind;
  }
  // No measured current circle (measured id only >= 0): no table from an
  // invented current limit, on either path.
  const fit::Calibration no_circle = WithoutCurrentCircle(fitted.cal);
  ASSERT_EQ(no_circle.MeasuredCurrentLimitA(), 0.0);
  spec.kind = "mtpa";
  auto local = ExportCalibration(no_circle, spec, tables::ExportRequest{}, "csv");
  ASSERT_EQ(local.status().code(), absl::StatusCode::kInvalidArgument) << local.status();
  EXPECT_EQ(local.status().message().rfind("flag --i-max-a: ", 0), 0u) << local.status();
  ASSERT_TRUE(AddFailedCalibration(*fitted.store, "IPM-L", no_circle).ok());
  tables::ExportRequest rpc;
  rpc.names_flags = false;
  auto stored = ExportTable(*fitted.store, "IPM-L", 2, spec, rpc, "csv");
  ASSERT_EQ(stored.status().code(), absl::StatusCode::kInvalidArgument) << stored.status();
  EXPECT_EQ(stored.status().message().rfind("i_max_a: ", 0), 0u) << stored.status();
  // Given, the limit is taken on both paths alike.
  tables::ExportRequest given;
  given.i_max_a = 80;
  given.names_flags = false;
  spec.allow_extrapolation = true;   // 80 A lies beyond the (empty) measured region
  local = ExportCalibration(no_circle, spec, given, "csv");
  stored = ExportTable(*fitted.store, "IPM-L", 2, spec, given, "csv");
  ASSERT_TRUE(local.ok()) << local.status();
  ASSERT_TRUE(stored.ok()) << stored.status();
  EXPECT_EQ(local->limits.limits.i_max_a, 80);
  EXPECT_EQ(local->exported.payload_sha256, stored->exported.payload_sha256);
  // A format name is checked before any table is computed, on both paths.
  EXPECT_EQ(ExportCalibration(fitted.cal, spec, given, "xlsx").status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ExportTable(*fitted.store, "IPM-L", 1, spec, given, "xlsx").status().code(),
            absl::StatusCode::kInvalidArgument);
}

// The service fits the model names `fluxcal fit --model` accepts, read by
// the one parser (fit::ParseModelName): "poly3x" was refused by the CLI's
// copy and fitted as poly3 by the service's std::stoi; now both refuse it.
TEST(Pipeline, FitTakesTheModelNamesTheCliTakes) {
  auto store = storage::Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(IngestHfRun(**store, "IPM-M", "st", kMotor, Grid(1.0)).ok());
  for (const char* bad : {"poly3x", "poly11", "spline0", "polyX", "Auto"}) {
    auto r = FitSerial(**store, "IPM-M", bad, {});
    ASSERT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << bad << ": " << r.status();
    EXPECT_NE(r.status().message().find("got '" + std::string(bad) + "'"), std::string::npos) << r.status();
    EXPECT_EQ(fit::ParseModelName(bad).status().code(), absl::StatusCode::kInvalidArgument) << bad;
  }
  auto ok = FitSerial(**store, "IPM-M", "poly3", {});
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_EQ(ok->model, "poly3");
  EXPECT_EQ(ok->version, 1) << "a refused name stores no version";
}

// The verdict never passes a calibration missing a fact it depends on: a
// station that stated no nominal psi_pm gets a fail that says so (before:
// pass, judged from the fit alone), and pole pairs are required at ingest.
TEST(Pipeline, VerdictNeedsTheNominalMagnetFlux) {
  auto store = storage::Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  EXPECT_EQ(IngestHfRun(**store, "IPM-V", "st", MotorNominal{0, 0.011, 0.0114}, Grid(1.0)).status().code(),
            absl::StatusCode::kInvalidArgument);
  ASSERT_TRUE(IngestHfRun(**store, "IPM-V", "st", MotorNominal{4, 0.011, 0.0}, Grid(1.0)).ok());
  auto row = FitSerial(**store, "IPM-V", "analytic", {});
  ASSERT_TRUE(row.ok()) << row.status();
  EXPECT_EQ(row->verdict.rfind("fail: nominal psi_pm unknown", 0), 0u) << row->verdict;
  auto cal = LoadCalibration(**store, "IPM-V", 0);
  ASSERT_TRUE(cal.ok());
  EXPECT_FALSE(cal->psi_pm_nominal_wb().has_value());
  EXPECT_FALSE(cal->udc_v().has_value()) << "an HF run states no Udc; none is invented";
  // The page of a calibration file without the nominal psi_pm: no pass.
  report::ReportInputs in;
  FillReportInputsFromJson(*cal, cal->ToJson(), &in);
  EXPECT_EQ(in.verdict.rfind("fail: nominal psi_pm unknown", 0), 0u) << in.verdict;
  // A nominal given to the verdict (the manifest's, with --set) is judged:
  // here the fit had no prior, and inductances alone do not observe psi_pm
  // (it stayed near the fit's start value), which the verdict then shows.
  EXPECT_EQ(Verdict(*cal, 0.0114, 36, 0, {}).rfind("fail: psi_pm", 0), 0u) << Verdict(*cal, 0.0114, 36, 0, {});
}

// Machine facts for a fit (pipeline/facts.h): the source's, a flag's where
// the source says nothing, a contradiction refused, what a calibration
// cannot do without named by its flag.
TEST(Facts, StatedMergedOrRefused) {
  fit::FitData bare;
  bare.inductances.push_back(ToObservation(Grid(1.0)[7]));
  fit::FitData d = bare;
  auto st = ApplyStatedFacts({}, FactSource::kHfResults, &d);
  ASSERT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  for (const char* flag : {"--serial", "--pole-pairs", "--psi-pm-wb", "not observable"}) {
    EXPECT_NE(st.message().find(flag), std::string::npos) << flag << " in " << st;
  }
  StatedFacts flags;
  flags.serial = "IPM-S-1";
  flags.pole_pairs = 4;
  flags.psi_pm_wb = 0.0114;
  std::vector<std::string> notes;
  ASSERT_TRUE(ApplyStatedFacts(flags, FactSource::kHfResults, &d, &notes).ok());
  EXPECT_EQ(d.serial, "IPM-S-1");
  EXPECT_EQ(d.pole_pairs, 4);
  EXPECT_EQ(*d.psi_pm_prior_wb, 0.0114);
  EXPECT_FALSE(d.rs_ohm || d.udc_v) << "not stated: unknown";
  EXPECT_EQ(notes.size(), 3u);
  // Steady-state rows at speed observe psi_pm: no --psi-pm-wb needed.
  fit::FitData with_rows = bare;
  with_rows.steady_state.push_back({-20, 40, 2000, -3, 9, std::nullopt});
  flags.psi_pm_wb.reset();
  EXPECT_TRUE(ApplyStatedFacts(flags, FactSource::kRecordingSet, &with_rows).ok());
  // A set's facts: an equal flag is fine, a different one refused, naming both.
  fit::FitData set = d;
  flags = {};
  flags.pole_pairs = 4;
  flags.udc_v = 48;
  ASSERT_TRUE(ApplyStatedFacts(flags, FactSource::kRecordingSet, &set).ok());
  EXPECT_EQ(*set.udc_v, 48.0) << "fills what the set does not state";
  flags.udc_v = 50;
  st = ApplyStatedFacts(flags, FactSource::kRecordingSet, &set);
  ASSERT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("flag --udc-v: 50 differs from the set's manifest's udc_v 48"), std::string::npos) << st;
  flags = {};
  flags.pole_pairs = 101;
  EXPECT_NE(ApplyStatedFacts(flags, FactSource::kRecordingSet, &set).message().find("flag --pole-pairs"),
            std::string::npos);
}

// The stored version's page: the store's provenance on it, the fleet at
// FleetStatistics' default points, the deadline honoured between steps
// and inside the fleet, NotFound for what is not stored.
TEST(Pipeline, StoredReport) {
  auto store = storage::Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(IngestHfRun(**store, "IPM-R", "st", kMotor, Grid(1.0)).ok());
  ASSERT_TRUE(IngestHfRun(**store, "IPM-S", "st", kMotor, Grid(1.05)).ok());
  ASSERT_TRUE(FitSerial(**store, "IPM-R", "analytic", {}).ok());
  ASSERT_TRUE(FitSerial(**store, "IPM-S", "analytic", {}).ok());
  auto rep = BuildStoredReport(**store, "IPM-R", 0);
  ASSERT_TRUE(rep.ok()) << rep.status();
  EXPECT_EQ(rep->version, 1);
  EXPECT_EQ(rep->verdict, "pass");
  EXPECT_EQ(rep->html_sha256, io::Sha256Hex(rep->page.html));
  const std::string& html = rep->page.html;
  EXPECT_NE(html.find("<th>calibration created</th><td>" + (*store)->GetCalibration("IPM-R", 1)->created_utc),
            std::string::npos);
  EXPECT_NE(html.find("<th>release state</th><td>not released</td>"), std::string::npos);
  EXPECT_NE(html.find("<th>calibration from</th><td>IPM-R version 1 from the service's store</td>"),
            std::string::npos) << html.substr(html.find("calibration from"), 120);
  ASSERT_TRUE(rep->fleet_included);
  for (const auto& [id, iq] : kDefaultFleetPointsA) {
    EXPECT_NE(html.find(absl::StrFormat("<td>%.4g A, %.4g A</td><td>2</td>", id, iq)), std::string::npos) << id;
  }
  StoredReportOptions no_fleet;
  no_fleet.include_fleet = false;
  rep = BuildStoredReport(**store, "IPM-R", 1, no_fleet);
  ASSERT_TRUE(rep.ok());
  EXPECT_FALSE(rep->fleet_included);
  EXPECT_EQ(rep->page.html.find("<h2>Fleet</h2>"), std::string::npos);

  EXPECT_EQ(BuildStoredReport(**store, "IPM-R", 2).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(BuildStoredReport(**store, "IPM-NONE", 0).status().code(), absl::StatusCode::kNotFound);
  // Cancelled at the first poll (after reading the version), and inside
  // the fleet (the third poll: the step before, then one per calibration).
  for (int stop_at : {1, 3}) {
    int polls = 0;
    auto stopped = BuildStoredReport(**store, "IPM-R", 0, {}, [&] { return ++polls >= stop_at; });
    EXPECT_EQ(stopped.status().code(), absl::StatusCode::kCancelled) << stop_at;
    EXPECT_EQ(polls, stop_at);
  }
}

// What a page takes from a calibration's JSON, a file's or the store's:
// a stored verdict as stored, else the fit's own; the findings a diagnosed
// calibration carries (another format is left out, not fatal).
TEST(Pipeline, ReportInputsFromTheCalibrationJson) {
  auto store = StoreWithAnalyticFit("IPM-J");
  ASSERT_TRUE(store.ok()) << store.status();
  auto cal = LoadCalibration(**store, "IPM-J", 0);
  ASSERT_TRUE(cal.ok());
  nlohmann::json j = cal->ToJson();
  report::ReportInputs in;
  FillReportInputsFromJson(*cal, j, &in);
  EXPECT_EQ(in.calibration, &*cal);
  EXPECT_EQ(in.verdict, Verdict(*cal, std::nullopt, 0, 0, {}));
  EXPECT_EQ(in.verdict_basis.rfind("from the fit and the calibration's nominal psi_pm", 0), 0u) << in.verdict_basis;
  EXPECT_FALSE(in.diagnosis.has_value());
  EXPECT_FALSE(in.software_version.empty());
  j["verdict"] = "fail: stored reason";
  j["diagnosis"] = {{"format", "fluxcal.diagnosis.v1"}, {"verdict", "explained"},
                    {"findings", {{{"effect", "dead_time"}, {"parameters", {{"dead_time_s", 2.5e-6}}}}}}};
  report::ReportInputs marked;
  FillReportInputsFromJson(*cal, j, &marked);
  EXPECT_EQ(marked.verdict, "fail: stored reason");
  EXPECT_EQ(marked.verdict_basis, "as stored with the calibration");
  ASSERT_TRUE(marked.diagnosis.has_value());
  EXPECT_EQ((*marked.diagnosis)["serial"], "IPM-J");
  EXPECT_EQ((*marked.diagnosis)["findings"][0]["effect"], "dead_time");
  auto page = report::BuildReport(marked);
  ASSERT_TRUE(page.ok()) << page.status();
  EXPECT_NE(page->html.find("<td>dead_time</td>"), std::string::npos);
  j["diagnosis"]["format"] = "something.else";
  report::ReportInputs other;
  FillReportInputsFromJson(*cal, j, &other);
  EXPECT_FALSE(other.diagnosis.has_value());
  j["diagnosis"] = "not an object";
  FillReportInputsFromJson(*cal, j, &other);
  EXPECT_FALSE(other.diagnosis.has_value());
}

// Identified points of a simulated set go through the one converter; the
// identify-then-fit glue feeds the fit exactly those points.
TEST(Pipeline, IdentifiedPointsFeedTheFitUnchanged) {
  sim::TwinConfig cfg;
  cfg.serial = "IPM-ID-1";
  sim::Plan plan = sim::DefaultPlan();
  plan.record_s = 0.02;
  auto r = sim::Simulate(cfg, plan);
  ASSERT_TRUE(r.ok());
  auto ids = IdentifySet(r->set);
  ASSERT_TRUE(ids.ok());
  EXPECT_EQ(ids->points.size() + ids->failures.size(), ids->results.size());
  EXPECT_GE(ids->points.size(), 30u);
  auto data = FitDataFromSet(r->set);
  ASSERT_TRUE(data.ok());
  EXPECT_EQ(data->inductances.size(), ids->points.size());
  for (size_t k = 0; k < ids->points.size(); ++k) {
    const auto o = ToObservation(ids->points[k]);
    EXPECT_EQ(o.ldd_h, data->inductances[k].ldd_h);
    EXPECT_EQ(o.id_a, data->inductances[k].id_a);
    // The injection's flux radius (5 V at 500 Hz: 1.59 mWb) travels with
    // the point, so that a stored fit predicts it as the local one does.
    ASSERT_TRUE(o.hf_flux_radius_wb.has_value());
    EXPECT_EQ(o.hf_flux_radius_wb, data->inductances[k].hf_flux_radius_wb);
    EXPECT_NEAR(*o.hf_flux_radius_wb, 5.0 / (2 * 3.14159265358979 * 500), 0.05e-3);
    EXPECT_EQ(FromProto(ToProto(ids->points[k])).hf_flux_radius_wb, ids->points[k].hf_flux_radius_wb);
  }
}

// The stored path fits as the local one does: a machine whose injection
// sweeps a knee (the bridge-knee trait motor), its identified points sent
// with their flux radius, stored and fitted, gives the calibration the
// same points give locally, and both kept the large-signal HF model
// (docs/fitting.md, "Large-signal HF").
TEST(Pipeline, StoredFitPredictsTheInjectionAsTheLocalFit) {
  sim::MotorTraits bridge;
  for (const auto& t : sim::RealLikeMotors(100.0, 0.15)) {
    if (t.name == "ipm-bridge") bridge = t;
  }
  ASSERT_EQ(bridge.name, "ipm-bridge");
  sim::TwinConfig cfg;
  cfg.seed = 31;
  cfg.serial = "IPM-KNEE";
  cfg.motor.sat.psi_pm_wb = bridge.psi_pm_wb;
  cfg.magnetics = std::make_shared<sim::TraitMotor>(bridge);
  cfg.control.gain_scheduled = true;
  auto r = sim::Simulate(cfg, sim::DefaultPlan());
  ASSERT_TRUE(r.ok()) << r.status();
  auto ids = IdentifySet(r->set);
  ASSERT_TRUE(ids.ok());
  const MotorNominal motor{r->set.manifest.motor.pole_pairs, *r->set.manifest.motor.rs_ohm,
                           *r->set.manifest.motor.psi_pm_wb};
  // Over the wire and into the store.
  std::vector<IdentifiedPoint> sent;
  for (const auto& p : ids->points) sent.push_back(FromProto(ToProto(p)));
  auto store = storage::Store::Open(":memory:");
  ASSERT_TRUE(store.ok());
  ASSERT_TRUE(IngestHfRun(**store, "IPM-KNEE", "st", motor, sent).ok());
  auto row = FitSerial(**store, "IPM-KNEE", "auto", {});
  ASSERT_TRUE(row.ok()) << row.status();
  auto stored = ParseStoredCalibration(*row);
  ASSERT_TRUE(stored.ok()) << stored.status();
  // Locally: the same points, the manifest's facts.
  fit::FitData local_data;
  local_data.serial = "IPM-KNEE";
  local_data.pole_pairs = motor.pole_pairs;
  local_data.rs_ohm = motor.rs_ohm;
  local_data.psi_pm_prior_wb = motor.psi_pm_wb;
  for (const auto& p : ids->points) local_data.inductances.push_back(ToObservation(p));
  auto local = fit::Fit(local_data, {});
  ASSERT_TRUE(local.ok()) << local.status();
  for (const fit::Calibration* c : {&*stored, &*local}) {
    ASSERT_FALSE(c->summary.candidates.empty());
    EXPECT_NE(c->summary.candidates.back().find("large-signal kept"), std::string::npos)
        << c->summary.candidates.back();
  }
  for (double id : {-80.0, -40.0, 0.0}) {
    for (double iq : {10.0, 40.0, 90.0}) {
      const auto a = stored->Flux(id, iq), b = local->Flux(id, iq);
      EXPECT_NEAR(a.psi_d_wb, b.psi_d_wb, 1e-9) << id << ", " << iq;
      EXPECT_NEAR(a.psi_q_wb, b.psi_q_wb, 1e-9) << id << ", " << iq;
    }
  }
}

TEST(Pipeline, WireConverterRoundTrips) {
  for (const auto& p : Grid(1.0)) {
    auto q = p;
    q.reliable = false;
    q.temperature_c = 71.5;
    q.speed_rpm = -1234.5;
    const auto back = FromProto(ToProto(q));
    EXPECT_EQ(back.point_id, q.point_id);
    EXPECT_EQ(back.ld_h, q.ld_h);
    EXPECT_EQ(back.ldq_h, q.ldq_h);
    EXPECT_EQ(back.speed_rpm, q.speed_rpm);
    EXPECT_EQ(back.temperature_c, q.temperature_c);
    EXPECT_FALSE(back.reliable);
    q.ldq_h.reset();
    EXPECT_FALSE(FromProto(ToProto(q)).ldq_h.has_value()) << "an absent Ldq must stay absent, not become 0";
  }
}

// The stream digests have the form docs/service.md documents: the golden
// values were computed by an independent implementation (Python's
// struct.pack(">I"/">Q"/">d") and hashlib, the same bytes clients/python
// hashes), so a change of the form breaks this test, not only the clients.
TEST(IngestStream, DigestsHaveTheDocumentedForm) {
  IdentifiedPoint a;
  a.point_id = "p0"; a.id_a = -20; a.iq_a = 40; a.speed_rpm = 1500; a.ld_h = 1.8e-4; a.lq_h = 3.6e-4;
  a.ldq_h = -1.25e-6; a.ld_h_std = 1e-7; a.lq_h_std = 2e-7; a.ldq_h_std = 3e-7; a.temperature_c = 25;
  a.reliable = true;
  IdentifiedPoint b;
  b.point_id = "p1"; b.id_a = 0; b.iq_a = 100; b.speed_rpm = 0; b.ld_h = 2e-4; b.lq_h = 4e-4;
  b.ld_h_std = b.lq_h_std = b.ldq_h_std = 0; b.temperature_c = 31.5; b.reliable = false;
  EXPECT_EQ(HfPointsSha256({a, b}), "22e7c253c7ba13bdab6539be3f8fba08288e5e31a45100ad0037a57d316856df");
  EXPECT_EQ(HfPointsSha256({}), "f376d611f1a11eda516bf01adf882c09d600e292c1b98d6384dcfd475ae6ccfa");
  // Every bit counts; order counts; an absent Ldq is not Ldq = 0.
  IdentifiedPoint c = a;
  c.ld_h = std::nextafter(c.ld_h, 1.0);
  EXPECT_NE(HfPointsSha256({c, b}), HfPointsSha256({a, b}));
  EXPECT_NE(HfPointsSha256({b, a}), HfPointsSha256({a, b}));
  IdentifiedPoint d = b;
  d.ldq_h = 0.0;
  EXPECT_NE(HfPointsSha256({a, d}), HfPointsSha256({a, b}));
  // A zero's sign does not count (SQLite gives -0.0 back as +0.0).
  IdentifiedPoint e = b;
  e.id_a = -0.0;
  EXPECT_EQ(HfPointsSha256({a, e}), HfPointsSha256({a, b}));
  // The injection's flux radius, where stated, is appended as the byte 'r'
  // and its value (golden value: Python, b"r" + struct.pack(">d", 1.6e-3)
  // after the reliable byte); absent, the digest is the one above.
  IdentifiedPoint g = b;
  g.hf_flux_radius_wb = 1.6e-3;
  EXPECT_EQ(HfPointsSha256({a, g}), "2f7393121b26de7d2f55bd26262e6038ba2cb0a45d4ad3381cfa548a15a8aaf8");
  const io::RecordingFiles files = {
      {"manifest.json", "{}"}, {"points/p000.csv", "t_s,ia_a\n0,1\n"}, {"empty.csv", ""}};
  EXPECT_EQ(RecordingFilesSha256(files), "f11252fe1fd7038a64859e532eee696fde5c8288620077ea4fa227a6b75315b3");
  EXPECT_EQ(RecordingFilesBytes(files), 15);
  io::RecordingFiles shorter = files;
  shorter["points/p000.csv"].pop_back();
  EXPECT_NE(RecordingFilesSha256(shorter), RecordingFilesSha256(files));
}

TEST(IngestStream, DeclaredAndStoredTotalsAreCompared) {
  const StreamTotals sent{38, 36, 0, std::string(64, 'a')};
  EXPECT_TRUE(CheckStreamEnd(sent, sent, "end", "points").ok());
  StreamTotals got = sent;
  got.messages = 20;
  got.count = 18;
  auto s = CheckStreamEnd(sent, got, "end", "points");
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("end.messages: the stream declares 38 messages, the service received 20 messages"),
            std::string::npos) << s;
  got.messages = 38;
  s = CheckStreamEnd(sent, got, "chunks[9].end", "files");
  EXPECT_NE(s.message().find("chunks[9].end.count: the stream declares 36 files, the service received 18 files"),
            std::string::npos) << s;
  got = sent;
  got.sha256 = std::string(64, 'b');
  EXPECT_NE(CheckStreamEnd(sent, got, "end", "points").message().find("end.sha256"), std::string::npos);
  // The client's side: stored against sent.
  got = sent;
  got.messages = 0;   // not compared
  EXPECT_TRUE(CheckStored(sent, got, "points").ok());
  got.count = 18;
  s = CheckStored(sent, got, "points");
  EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(s.message().find("the service stored 18 points, this client sent 36"), std::string::npos) << s;
  got = sent;
  got.sha256.clear();
  s = CheckStored(sent, got, "points");
  EXPECT_NE(s.message().find("missing (a service without stream digests)"), std::string::npos) << s;
}

// Anchor files: a snapshot and event lines fold into one anchor (per serial
// the highest version, the highest release); a malformed line is named by
// file, line and field.
TEST(Anchor, FileFoldsItsLinesAndNamesAMalformedOne) {
  const std::string path = Temp("anchor.jsonl");
  fs::remove(path);
  EXPECT_EQ(ReadAnchorFile(path).status().code(), absl::StatusCode::kNotFound);
  storage::ChainHead snap;
  snap.calibrations = {{"IPM-1", 2, std::string(64, '1')}, {"IPM-2", 5, std::string(64, '2')}};
  snap.release_seq = 3;
  snap.release_serial = "IPM-2";
  snap.release_version = 5;
  snap.release_sha256 = std::string(64, '3');
  snap.digest_sha256 = storage::ChainHeadDigest(snap);
  ASSERT_TRUE(AppendAnchorLine(path, AnchorLine(snap, "snapshot", "sqlite", "2030-01-01T00:00:00Z")).ok());
  storage::ChainHead event;
  event.calibrations = {{"IPM-1", 3, std::string(64, '4')}};
  event.release_seq = 3;
  event.release_serial = "IPM-2";
  event.release_version = 5;
  event.release_sha256 = std::string(64, '3');
  ASSERT_TRUE(AppendAnchorLine(path, AnchorLine(event, "event", "sqlite", "2030-01-02T00:00:00Z")).ok());
  auto a = ReadAnchorFile(path);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->lines, 2);
  EXPECT_EQ(a->newest_utc, "2030-01-02T00:00:00Z");
  ASSERT_EQ(a->head.calibrations.size(), 2u);
  EXPECT_EQ(a->head.calibrations[0].version, 3);
  EXPECT_EQ(a->head.calibrations[0].row_sha256, std::string(64, '4'));
  EXPECT_EQ(a->head.calibrations[1].version, 5);
  EXPECT_EQ(a->head.release_seq, 3);
  const auto first = nlohmann::json::parse(AnchorLine(snap, "snapshot", "sqlite", "2030-01-01T00:00:00Z"));
  EXPECT_EQ(first["format"], "fluxcal.chain-anchor.v1");
  EXPECT_EQ(first["digest_sha256"], snap.digest_sha256);
  std::ofstream(path, std::ios::app) << "{\"format\": \"fluxcal.chain-anchor.v1\", \"created_utc\": \"x\", "
                                        "\"calibrations\": [{\"serial\": \"IPM-1\", \"version\": 4, \"row_sha256\": \"zz\"}]}\n";
  auto bad = ReadAnchorFile(path);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find(path + ":3: field 'calibrations[0].row_sha256'"), std::string::npos)
      << bad.status();
  fs::remove(path);
  std::ofstream(path).close();
  EXPECT_EQ(ReadAnchorFile(path).status().code(), absl::StatusCode::kInvalidArgument);
  fs::remove(path);
}

// The repros of issue 24 through the commands an operator runs, on a SQLite
// store edited behind the service:
//  - the newest version deleted with its chain row: `verify-db` alone says
//    intact; with the anchor `admin anchor` wrote before, it names the
//    serial and version;
//  - a release INSERTed for a failing version: `verify-db` names it, and
//    the flasher's path (FlashableVersion) refuses it.
TEST(Admin, AnchorAndVerifyDbFindWhatTheChainsAloneMiss) {
  const std::string db = Temp("anchor_cli.db"), anchor = Temp("anchor_cli.jsonl");
  RemoveDb(db);
  fs::remove(anchor);
  {
    auto s = storage::Store::Open(db);
    ASSERT_TRUE(s.ok());
    ASSERT_TRUE(IngestHfRun(**s, "IPM-AN-1", "st", kMotor, Grid(1.0)).ok());
    ASSERT_EQ(FitSerial(**s, "IPM-AN-1", "analytic", {})->verdict, "pass");
    auto noisy = Grid(1.0);   // 8 % scatter fails the 2 % residual policy
    for (size_t k = 0; k < noisy.size(); ++k) noisy[k].lq_h *= k % 2 ? 1.08 : 0.92;
    ASSERT_TRUE(IngestHfRun(**s, "IPM-AN-1", "st", std::nullopt, noisy).ok());
    const auto v2 = FitSerial(**s, "IPM-AN-1", "analytic", {});
    ASSERT_TRUE(v2.ok());
    ASSERT_NE(v2->verdict, "pass");
    ASSERT_TRUE((*s)->Release("IPM-AN-1", 1, "rel").ok());
    EXPECT_EQ(*FlashableVersion(**s, "IPM-AN-1", 0), 1);
  }
  auto run = [](const std::string& cmd) {
    std::string out;
    FILE* p = popen((cmd + " 2>&1").c_str(), "r");
    char buf[512];
    while (p && fgets(buf, sizeof buf, p)) out += buf;
    const int rc = p ? pclose(p) : -1;
    return std::make_pair(WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, out);
  };
  const std::string bin = FLUXCAL_BINARY;
  auto [arc, aout] = run(bin + " admin anchor --db " + db + " --out " + anchor + " --json");
  ASSERT_EQ(arc, 0) << aout;
  const auto doc = nlohmann::json::parse(aout);
  EXPECT_EQ(doc["calibrations"][0]["version"], 2);
  EXPECT_EQ(doc["release"]["seq"], 1);
  EXPECT_EQ(doc["digest_sha256"].get<std::string>().size(), 64u);
  EXPECT_EQ(run(bin + " admin verify-db --db " + db + " --anchor " + anchor).first, 0);
  auto raw = [&](const std::string& sql) {
    auto d = storage::Database::Open(db);
    return d.ok() && (*d)->Exec(sql).ok();
  };
  ASSERT_TRUE(raw("DROP TRIGGER calibrations_no_delete; DROP TRIGGER chain_no_delete; "
                  "DELETE FROM calibration_chain WHERE serial = 'IPM-AN-1' AND version = 2; "
                  "DELETE FROM calibrations WHERE serial = 'IPM-AN-1' AND version = 2"));
  auto [brc, bout] = run(bin + " admin verify-db --db " + db);
  EXPECT_EQ(brc, 0) << "the chains alone cannot see it: " << bout;
  auto [vrc, vout] = run(bin + " admin verify-db --db " + db + " --anchor " + anchor + " --json");
  EXPECT_EQ(vrc, 1) << vout;
  const auto rep = nlohmann::json::parse(vout);
  EXPECT_FALSE(rep["intact"].get<bool>());
  ASSERT_EQ(rep["problems"].size(), 1u) << vout;
  EXPECT_EQ(rep["problems"][0].get<std::string>().rfind("IPM-AN-1 v2: removed after the anchor in " + anchor, 0), 0u)
      << vout;
  // A failing version made flashable behind the service.
  ASSERT_TRUE(raw("INSERT INTO calibrations SELECT serial, 2, run_id, created_utc, model, psi_pm_wb, rms_relative, "
                  "'fail: psi_pm', calibration_json, model_pb FROM calibrations WHERE serial = 'IPM-AN-1' AND version = 1; "
                  "INSERT INTO releases (serial, version, released_by, released_utc) "
                  "VALUES ('IPM-AN-1', 2, 'someone', '2030-01-01T00:00:00Z')"));
  auto [irc, iout] = run(bin + " admin verify-db --db " + db);
  EXPECT_EQ(irc, 1) << iout;
  EXPECT_NE(iout.find("IPM-AN-1 v2: release without a chain link (inserted around the service)"), std::string::npos)
      << iout;
  EXPECT_NE(iout.find("IPM-AN-1 v2: no chain link (row inserted around the store)"), std::string::npos) << iout;
  {
    auto s = storage::Store::Open(db);
    ASSERT_TRUE(s.ok());
    auto flash = FlashableVersion(**s, "IPM-AN-1", 0);
    EXPECT_EQ(flash.status().code(), absl::StatusCode::kDataLoss) << flash.status();
    EXPECT_EQ(*FlashableVersion(**s, "IPM-AN-1", 1), 1) << "the honest release stays flashable";
  }
  RemoveDb(db);
  fs::remove(anchor);
}

// A store with everything in it: runs, a raw recording, calibrations.
void Populate(storage::Store& s) {
  ASSERT_TRUE(IngestHfRun(s, "IPM-M-1", "st1", kMotor, Grid(1.0)).ok());
  ASSERT_TRUE(IngestHfRun(s, "IPM-M-2", "st2", kMotor, Grid(1.01)).ok());
  ASSERT_TRUE(FitSerial(s, "IPM-M-1", "analytic", {}).ok());
  ASSERT_TRUE(FitSerial(s, "IPM-M-1", "analytic", {}).ok());
  std::vector<uint8_t> blob(3000);
  for (size_t k = 0; k < blob.size(); ++k) blob[k] = static_cast<uint8_t>(k * 31);
  ASSERT_TRUE(s.IngestHfRun({"IPM-M-2", 4, 0.011, 0.0114, ""}, "st2", "recording", Grid(1.0), "feed", blob, 9000).ok());
}

TEST(Admin, MigrateSqliteToPostgresKeepsEverything) {
  std::string why;
  auto* pg = fluxcal::testing::SharedPgCluster(&why);
  FLUXCAL_PG_OR_SKIP(pg, why, "PostgreSQL migration test skipped");
  const std::string src = Temp("migrate_src.db");
  RemoveDb(src);
  auto from = storage::Store::Open("sqlite:" + src);
  ASSERT_TRUE(from.ok());
  Populate(**from);
  // An idempotency key, audited writes, a release and chain links go along.
  storage::AuditContext audit;
  audit.row.identity = "station-9"; audit.row.role = "station"; audit.row.peer = "ipv4:127.0.0.1:9";
  audit.row.request_id = "req-9"; audit.row.rpc = "IngestHfResults"; audit.row.serial = "IPM-M-3";
  audit.detail = [](int64_t run, bool) { return "run " + std::to_string(run); };
  ASSERT_TRUE(IngestHfRun(**from, "IPM-M-3", "st9", kMotor, Grid(1.0), 0, "key-9", nullptr, &audit).ok());
  audit.row.rpc = "Fit";
  audit.detail = nullptr;
  auto fitted = FitSerial(**from, "IPM-M-3", "analytic", {}, &audit);
  ASSERT_TRUE(fitted.ok()) << fitted.status();
  ASSERT_EQ(fitted->verdict, "pass");
  audit.row.rpc = "Release";
  audit.row.detail = "released version 1";
  ASSERT_TRUE((*from)->Release("IPM-M-3", 1, "rel-1", &audit).ok());
  ASSERT_TRUE(pg->CreateDatabase("migrated"));
  auto to = storage::Store::Open(pg->Url("migrated"));
  ASSERT_TRUE(to.ok()) << to.status();
  auto r = Migrate(**from, **to);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->motors, 3);
  EXPECT_EQ(r->runs, 4);
  EXPECT_EQ(r->points, 144);
  EXPECT_EQ(r->recordings, 1);
  EXPECT_EQ(r->calibrations, 3);
  EXPECT_EQ(r->releases, 1);
  EXPECT_EQ(r->audit_rows, 3);
  EXPECT_EQ(r->chain_links, 3);
  EXPECT_EQ(r->release_links, 1);
  EXPECT_EQ(*ContentHash(**to), *ContentHash(**from));
  EXPECT_TRUE(*(*to)->IsReleased("IPM-M-3", 1));
  auto trail_from = (*from)->AuditOf("IPM-M-3"), trail_to = (*to)->AuditOf("IPM-M-3");
  ASSERT_EQ(trail_to->size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(trail_to->at(k).id, trail_from->at(k).id);
    EXPECT_EQ(trail_to->at(k).utc, trail_from->at(k).utc);
    EXPECT_EQ(trail_to->at(k).detail, trail_from->at(k).detail);
  }
  auto chain = storage::VerifyChains(**to);
  ASSERT_TRUE(chain.ok()) << chain.status();
  EXPECT_EQ(chain->chained, 3);
  EXPECT_EQ(chain->unchained, 0);
  EXPECT_EQ(chain->releases_chained, 1);
  EXPECT_TRUE(chain->problems.empty());
  EXPECT_TRUE(storage::VerifyReleasedVersion(**to, "IPM-M-3", 1).ok()) << "the copy is flashable as the source was";
  bool replayed = false;
  auto again = IngestHfRun(**to, "IPM-M-3", "st9", kMotor, Grid(1.0), 0, "key-9", &replayed);
  ASSERT_TRUE(again.ok());
  EXPECT_TRUE(replayed) << "an idempotency key must survive the migration";
  // The migrated store serves: the same calibration, and version 3 next.
  EXPECT_EQ((*to)->GetCalibration("IPM-M-1", 2)->calibration_json, (*from)->GetCalibration("IPM-M-1", 2)->calibration_json);
  auto v3 = FitSerial(**to, "IPM-M-1", "analytic", {});
  ASSERT_TRUE(v3.ok());
  EXPECT_EQ(v3->version, 3);
  // A change anywhere changes the hash; a second migrate into it is refused.
  EXPECT_TRUE(storage::VerifyChains(**to)->problems.empty());
  EXPECT_EQ(storage::VerifyChains(**to)->chained, 4);
  EXPECT_NE(*ContentHash(**to), *ContentHash(**from));
  EXPECT_EQ(Migrate(**from, **to).status().code(), absl::StatusCode::kFailedPrecondition);
  // The same through the command an operator runs, checked by `admin hash`.
  ASSERT_TRUE(pg->CreateDatabase("migrated_cli"));
  auto run = [](const std::string& cmd) {
    std::string out;
    FILE* p = popen(cmd.c_str(), "r");
    char buf[512];
    while (p && fgets(buf, sizeof buf, p)) out += buf;
    const int rc = p ? pclose(p) : -1;
    return std::make_pair(rc, out);
  };
  const std::string bin = FLUXCAL_BINARY;
  auto [rc, out] = run(bin + " admin migrate --from sqlite:" + src + " --to " + pg->Url("migrated_cli") + " --json");
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("\"verified\": true"), std::string::npos) << out;
  EXPECT_NE(out.find("\"points\": 144"), std::string::npos) << out;
  EXPECT_NE(out.find("\"audit_rows\": 3"), std::string::npos) << out;
  EXPECT_NE(out.find("\"releases\": 1"), std::string::npos) << out;
  auto [vrc, vout] = run(bin + " admin verify-db --db " + pg->Url("migrated_cli"));
  EXPECT_EQ(vrc, 0) << vout;
  auto [rc1, h1] = run(bin + " admin hash --db sqlite:" + src);
  auto [rc2, h2] = run(bin + " admin hash --db " + pg->Url("migrated_cli"));
  ASSERT_EQ(rc1, 0);
  ASSERT_EQ(rc2, 0);
  EXPECT_EQ(h1, h2);
  EXPECT_EQ(h1.size(), 65u);   // 64 hex digits and a newline
  EXPECT_NE(run(bin + " admin migrate --from sqlite:" + src + " --to " + pg->Url("migrated_cli") + " 2>&1").first, 0)
      << "a second migrate into a filled database must be refused";
  RemoveDb(src);
}

TEST(Admin, SqliteBackupAndTheCommand) {
  const std::string src = Temp("backup_src.db"), out = Temp("backup_out.db");
  RemoveDb(src);
  RemoveDb(out);
  {
    auto s = storage::Store::Open(src);
    ASSERT_TRUE(s.ok());
    Populate(**s);
  }
  // The command, as an operator runs it, while nothing else writes.
  const std::string cmd = std::string(FLUXCAL_BINARY) + " admin backup --db " + src + " --out " + out + " --json";
  FILE* p = popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string json;
  char buf[512];
  while (fgets(buf, sizeof buf, p)) json += buf;
  ASSERT_EQ(pclose(p), 0) << json;
  EXPECT_NE(json.find("\"equal\": true"), std::string::npos) << json;
  auto a = storage::Store::Open(src);
  auto b = storage::Store::Open(out);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(*ContentHash(**a), *ContentHash(**b));
  EXPECT_EQ((*b)->GetRecording("feed")->size(), 3000u);
  // Refuses to overwrite, and sends PostgreSQL users to pg_dump.
  EXPECT_NE(std::system((cmd + " > /dev/null 2>&1").c_str()), 0);
  EXPECT_EQ(std::system((std::string(FLUXCAL_BINARY) + " admin backup --db postgresql://x/y --out /tmp/x 2>&1 | grep -q pg_dump").c_str()), 0);
  RemoveDb(src);
  RemoveDb(out);
}

// The fit request's tolerances and the run's grid: policy of the
// application layer (the service only transports them).
TEST(Pipeline, RequestedTolerancesOnlyTighten) {
  auto d = pipeline::RequestedTolerances(0, 0);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->max_rms_relative, pipeline::FitTolerances{}.max_rms_relative);
  EXPECT_EQ(d->psi_pm_tolerance_relative, pipeline::FitTolerances{}.psi_pm_tolerance_relative);
  auto t = pipeline::RequestedTolerances(0.01, 0.05);
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(t->max_rms_relative, 0.01);
  EXPECT_EQ(t->psi_pm_tolerance_relative, 0.05);
  auto loose = pipeline::RequestedTolerances(0.5, 0);
  EXPECT_EQ(loose.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(loose.status().message().find("may only tighten"), std::string::npos);
  EXPECT_EQ(pipeline::RequestedTolerances(-1, 0).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(pipeline::RequestedTolerances(0, std::nan("")).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(Pipeline, DistinctOperatingPoints) {
  std::vector<pipeline::IdentifiedPoint> points(36);
  for (auto& p : points) p.id_a = -10, p.iq_a = 20;
  auto s = pipeline::CheckDistinctOperatingPoints(points);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("1 distinct operating points"), std::string::npos) << s.message();
  for (int k = 0; k < pipeline::kMinDistinctOperatingPoints; ++k) points[k].iq_a = 10.0 * k;
  EXPECT_TRUE(pipeline::CheckDistinctOperatingPoints(points).ok());
  EXPECT_TRUE(pipeline::CheckDistinctOperatingPoints({}).ok());   // an empty run is refused elsewhere
}

}  // namespace
}  // namespace fluxcal::pipeline
