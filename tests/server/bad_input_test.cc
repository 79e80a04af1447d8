// The bad-input suite: over 150 malformed, oversized, hostile or physically
// absurd requests across every RPC, against a store that holds a fitted
// motor (so refusals are not just NOT_FOUND). None may be accepted
// silently: each must fail (a bad point in a good stream fails the whole
// stream). Every message names a field, is printable and short.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>

#include <grpcpp/grpcpp.h>

#include "gtest/gtest.h"
#include "io/csv.h"
#include "server/service.h"
#include "server/validation.h"
#include "simulation/twin.h"
#include "storage/store.h"
#include "tests/server/test_support.h"

namespace fluxcal::server {
namespace {

namespace fs = std::filesystem;
using Stub = v1::CalibrationService::Stub;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

std::vector<v1::HfPoint> Grid() { return test_support::TwinGridPoints(); }

v1::MotorInfo Motor() {
  v1::MotorInfo m;
  m.set_pole_pairs(4); m.set_rs_ohm(0.011); m.set_psi_pm_wb(sim::MotorParams().sat.psi_pm_wb);
  return m;
}

// A call of rpc whose request names IPM-GOOD and is then changed by set.
template <class Req, class Resp>
std::function<grpc::Status(Stub*)> AboutGoodSerial(grpc::Status (Stub::*rpc)(grpc::ClientContext*, const Req&, Resp*),
                                                   std::function<void(Req*)> set) {
  return [rpc, set](Stub* st) {
    grpc::ClientContext c;
    Req q;
    q.set_serial("IPM-GOOD");
    set(&q);
    Resp r;
    return (st->*rpc)(&c, q, &r);
  };
}

// One IngestHfResults stream of the given messages.
grpc::Status Stream(Stub* stub, const std::vector<v1::IngestHfResultsRequest>& msgs, v1::IngestHfResultsResponse* r) {
  grpc::ClientContext ctx;
  auto w = stub->IngestHfResults(&ctx, r);
  for (const auto& m : msgs) {
    if (!w->Write(m)) break;
  }
  w->WritesDone();
  return w->Finish();
}

v1::IngestHfResultsRequest Msg(const std::string& serial, const std::vector<v1::HfPoint>& pts, bool motor = true) {
  v1::IngestHfResultsRequest m;
  m.set_serial(serial);
  if (motor) *m.mutable_motor() = Motor();
  for (const auto& p : pts) *m.add_points() = p;
  return m;
}

struct Case {
  std::string name;
  std::function<grpc::Status(Stub*)> run;
};

class BadInput : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    db_ = (fs::temp_directory_path() / ("fluxcal_bad_" + std::to_string(::getpid()) + ".db")).string();
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(db_ + sfx);
    store_ = std::move(*storage::Store::Open(db_)).release();
    service_ = new CalibrationServiceImpl(store_);
    int port = 0;
    server_ = StartServer(service_, "127.0.0.1:0", &port).release();
    stub_ = v1::CalibrationService::NewStub(
                grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials()))
                .release();
    v1::IngestHfResultsResponse r;
    ASSERT_TRUE(Stream(stub_, {Msg("IPM-GOOD", Grid())}, &r).ok());
    grpc::ClientContext c;
    v1::FitRequest f;
    f.set_serial("IPM-GOOD");
    v1::FitResponse fr;
    ASSERT_TRUE(stub_->Fit(&c, f, &fr).ok());
  }
  static void TearDownTestSuite() {
    server_->Shutdown();
    delete stub_;
    delete server_;
    delete service_;
    delete store_;
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(db_ + sfx);
  }
  static inline std::string db_;
  static inline storage::Store* store_ = nullptr;
  static inline CalibrationServiceImpl* service_ = nullptr;
  static inline grpc::Server* server_ = nullptr;
  static inline Stub* stub_ = nullptr;
};

std::vector<Case> Cases() {
  std::vector<Case> cs;
  auto add = [&](std::string name, std::function<grpc::Status(Stub*)> f) { cs.push_back({std::move(name), std::move(f)}); };
  const std::vector<std::string> bad_serials = {"", ".", "..", "a b", std::string(65, 'A'), "a\nb", "\xc3\xa9",
                                                "a/b", "../x", std::string(1 << 20, 'S')};

  // --- IngestHfResults: stream level.
  for (const auto& s : bad_serials) {
    add("IngestHfResults serial '" + io::Printable(s.substr(0, 20)) + "'", [s](Stub* st) {
      v1::IngestHfResultsResponse r;
      return Stream(st, {Msg(s, Grid())}, &r);
    });
  }
  add("IngestHfResults empty stream", [](Stub* st) { v1::IngestHfResultsResponse r; return Stream(st, {}, &r); });
  add("IngestHfResults two serials", [](Stub* st) {
    v1::IngestHfResultsResponse r;
    return Stream(st, {Msg("IPM-A1", Grid()), Msg("IPM-A2", Grid())}, &r);
  });
  add("IngestHfResults unknown serial without motor", [](Stub* st) {
    v1::IngestHfResultsResponse r;
    return Stream(st, {Msg("IPM-NEW-1", Grid(), false)}, &r);
  });
  for (const std::string& station : {std::string("st\n1"), std::string(65, 's'), std::string(1 << 20, 's'),
                                     std::string("st\x01"), std::string("\xff")}) {
    add("IngestHfResults station_id '" + io::Printable(station.substr(0, 10)) + "'", [station](Stub* st) {
      auto m = Msg("IPM-A3", Grid());
      m.set_station_id(station);
      v1::IngestHfResultsResponse r;
      return Stream(st, {m}, &r);
    });
  }
  for (auto [name, set] : std::vector<std::pair<std::string, std::function<void(v1::MotorInfo*)>>>{
           {"pole_pairs 0", [](v1::MotorInfo* m) { m->set_pole_pairs(0); }},
           {"pole_pairs -1", [](v1::MotorInfo* m) { m->set_pole_pairs(-1); }},
           {"pole_pairs 101", [](v1::MotorInfo* m) { m->set_pole_pairs(101); }},
           {"rs NaN", [](v1::MotorInfo* m) { m->set_rs_ohm(kNaN); }},
           {"rs -1", [](v1::MotorInfo* m) { m->set_rs_ohm(-1); }},
           {"rs 1e9", [](v1::MotorInfo* m) { m->set_rs_ohm(1e9); }},
           {"psi_pm inf", [](v1::MotorInfo* m) { m->set_psi_pm_wb(kInf); }},
           {"psi_pm -0.1", [](v1::MotorInfo* m) { m->set_psi_pm_wb(-0.1); }},
           {"psi_pm 1e3", [](v1::MotorInfo* m) { m->set_psi_pm_wb(1e3); }}}) {
    add("IngestHfResults motor " + name, [set](Stub* st) {
      auto m = Msg("IPM-A4", Grid());
      set(m.mutable_motor());
      v1::IngestHfResultsResponse r;
      return Stream(st, {m}, &r);
    });
  }
  add("IngestHfResults 36 copies of one point", [](Stub* st) {
    std::vector<v1::HfPoint> pts(36, Grid()[7]);
    for (int k = 0; k < 36; ++k) pts[k].set_point_id("c" + std::to_string(k));
    v1::IngestHfResultsResponse r;
    return Stream(st, {Msg("IPM-A5", pts)}, &r);
  });
  add("IngestHfResults over the point limit", [](Stub* st) {
    std::vector<v1::HfPoint> pts;
    for (int k = 0; k <= kMaxPointsPerStream; ++k) {
      v1::HfPoint p = Grid()[k % 36];
      p.set_point_id("q" + std::to_string(k));
      p.set_id_a(-100 + 1e-3 * k);
      pts.push_back(p);
    }
    v1::IngestHfResultsResponse r;
    return Stream(st, {Msg("IPM-A6", pts)}, &r);
  });
  add("IngestHfResults every point invalid", [](Stub* st) {
    auto pts = Grid();
    for (auto& p : pts) p.set_ld_h(-1);
    v1::IngestHfResultsResponse r;
    return Stream(st, {Msg("IPM-A7", pts)}, &r);
  });

  // --- IngestHfResults: one bad point in a good stream refuses the whole stream.
  using Setter = std::function<void(v1::HfPoint*, double)>;
  const std::vector<std::pair<std::string, Setter>> fields = {
      {"id_a", [](v1::HfPoint* p, double v) { p->set_id_a(v); }},
      {"iq_a", [](v1::HfPoint* p, double v) { p->set_iq_a(v); }},
      {"speed_rpm", [](v1::HfPoint* p, double v) { p->set_speed_rpm(v); }},
      {"ld_h", [](v1::HfPoint* p, double v) { p->set_ld_h(v); }},
      {"lq_h", [](v1::HfPoint* p, double v) { p->set_lq_h(v); }},
      {"ldq_h", [](v1::HfPoint* p, double v) { p->set_ldq_h(v); }},
      {"ld_h_std", [](v1::HfPoint* p, double v) { p->set_ld_h_std(v); }},
      {"lq_h_std", [](v1::HfPoint* p, double v) { p->set_lq_h_std(v); }},
      {"ldq_h_std", [](v1::HfPoint* p, double v) { p->set_ldq_h_std(v); }},
      {"temperature_c", [](v1::HfPoint* p, double v) { p->set_temperature_c(v); }},
      {"hf_flux_radius_wb", [](v1::HfPoint* p, double v) { p->set_hf_flux_radius_wb(v); }}};
  for (const auto& [field, set] : fields) {
    for (double v : {kNaN, kInf, -kInf, 1e300, -1e300}) {
      add("IngestHfResults point " + field + " = " + std::to_string(v), [field = field, set = set, v](Stub* st) {
        auto pts = Grid();
        set(&pts[5], v);
        v1::IngestHfResultsResponse r;
        auto s = Stream(st, {Msg("IPM-PT", pts)}, &r);
        if (!s.ok()) return s;
        if (r.rejects_size() == 1 && r.rejects(0).index() == 5 && r.accepted() == 35) {
          return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, r.rejects(0).message());
        }
        return grpc::Status::OK;
      });
    }
  }
  for (auto [name, set] : std::vector<std::pair<std::string, std::function<void(v1::HfPoint*)>>>{
           {"ld_h 1e-300", [](v1::HfPoint* p) { p->set_ld_h(1e-300); }},
           {"ld_h 0", [](v1::HfPoint* p) { p->set_ld_h(0); }},
           {"lq_h 1.5 H", [](v1::HfPoint* p) { p->set_lq_h(1.5); }},
           {"lq_h_std 1000x", [](v1::HfPoint* p) { p->set_lq_h_std(1000 * p->lq_h()); }},
           {"ld_h_std = ld_h", [](v1::HfPoint* p) { p->set_ld_h_std(p->ld_h()); }},
           {"duplicate point_id", [](v1::HfPoint* p) { p->set_point_id("p0"); }},
           {"point_id newline", [](v1::HfPoint* p) { p->set_point_id("p\n5"); }},
           {"point_id 1 MB", [](v1::HfPoint* p) { p->set_point_id(std::string(1 << 20, 'p')); }},
           {"temperature -300", [](v1::HfPoint* p) { p->set_temperature_c(-300); }},
           {"id_a 20 kA", [](v1::HfPoint* p) { p->set_id_a(2e4); }},
           {"hf_flux_radius_wb 0", [](v1::HfPoint* p) { p->set_hf_flux_radius_wb(0); }},
           {"hf_flux_radius_wb -1 mWb", [](v1::HfPoint* p) { p->set_hf_flux_radius_wb(-1e-3); }},
           {"hf_flux_radius_wb 11 Wb", [](v1::HfPoint* p) { p->set_hf_flux_radius_wb(11); }}}) {
    add("IngestHfResults point " + name, [set](Stub* st) {
      auto pts = Grid();
      set(&pts[5]);
      v1::IngestHfResultsResponse r;
      auto s = Stream(st, {Msg("IPM-PT", pts)}, &r);
      if (!s.ok()) return s;
      if (r.rejects_size() == 1 && r.accepted() == 35) {
        return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, r.rejects(0).message());
      }
      return grpc::Status::OK;
    });
  }

  // --- IngestRecording.
  auto chunks = [](std::vector<std::pair<std::string, std::string>> files, std::string serial,
                   std::string station) {
    return [files, serial, station](Stub* st) {
      v1::IngestRecordingResponse r;
      return test_support::UploadRecording(st, serial, station, files, &r);
    };
  };
  for (const std::string& name : std::vector<std::string>{"/etc/passwd", "../x", "a//b", "./m", "a b", "x\n1\ny", "a/b/c/d/e", "\t",
                                  "a\\b", "a:b", "", std::string(300, 'n')}) {
    add("IngestRecording path '" + io::Printable(name.substr(0, 20)) + "'",
        chunks({{"manifest.json", "{}"}, {name, "x"}}, "IPM-R1", ""));
  }
  add("IngestRecording empty stream", chunks({}, "IPM-R1", ""));
  add("IngestRecording no manifest", chunks({{"points/p0.csv", "t_s\n"}}, "IPM-R1", ""));
  add("IngestRecording manifest not JSON", chunks({{"manifest.json", "{"}}, "IPM-R1", ""));
  add("IngestRecording manifest 1e999", chunks({{"manifest.json", "{\"format\": 1e999}"}}, "IPM-R1", ""));
  add("IngestRecording manifest invalid UTF-8", chunks({{"manifest.json", "{\"serial\": \"\xff\"}"}}, "IPM-R1", ""));
  add("IngestRecording serial differs from manifest",
      chunks({{"manifest.json", "{\"format\":\"fluxcal.recording.v1\",\"serial\":\"OTHER\",\"motor\":{\"pole_pairs\":4},"
                                "\"drive\":{\"f_sample_hz\":10000},\"hf_results\":\"h.csv\"}"},
              {"h.csv", "id_a,iq_a,speed_rpm,ld_h,lq_h,ldq_h,temperature_c\n0,0,0,1e-4,2e-4,,\n"}},
             "IPM-R1", ""));
  for (const auto& s : bad_serials) {
    add("IngestRecording serial '" + io::Printable(s.substr(0, 20)) + "'", chunks({{"manifest.json", "{}"}}, s, ""));
  }
  add("IngestRecording station newline", chunks({{"manifest.json", "{}"}}, "IPM-R1", "a\nb"));

  // --- Fit.
  auto fit = [](std::string serial, double rms, double pm, std::string model) {
    return [=](Stub* st) {
      grpc::ClientContext c;
      v1::FitRequest q;
      q.set_serial(serial); q.set_max_rms_relative(rms); q.set_psi_pm_tolerance_relative(pm); q.set_model(model);
      v1::FitResponse r;
      return st->Fit(&c, q, &r);
    };
  };
  for (const auto& s : bad_serials) add("Fit serial '" + io::Printable(s.substr(0, 20)) + "'", fit(s, 0, 0, ""));
  add("Fit unknown serial", fit("IPM-NOPE", 0, 0, ""));
  for (double v : {-1.0, kNaN, kInf, 1e300, 0.5}) {
    add("Fit max_rms_relative " + std::to_string(v), fit("IPM-GOOD", v, 0, ""));
    add("Fit psi_pm_tolerance_relative " + std::to_string(v), fit("IPM-GOOD", 0, v, ""));
  }
  add("Fit unknown model", fit("IPM-GOOD", 0, 0, "neural"));

  // --- GetCalibration, History, Diagnose.
  for (int v : {-1, -2147483647, 999}) {
    add("GetCalibration version " + std::to_string(v), [v](Stub* st) {
      grpc::ClientContext c; v1::GetCalibrationRequest q; q.set_serial("IPM-GOOD"); q.set_version(v);
      v1::CalibrationRecord r; return st->GetCalibration(&c, q, &r);
    });
  }
  for (const auto& s : bad_serials) {
    add("History serial '" + io::Printable(s.substr(0, 20)) + "'", [s](Stub* st) {
      grpc::ClientContext c; v1::HistoryRequest q; q.set_serial(s); v1::HistoryResponse r; return st->History(&c, q, &r);
    });
    add("Diagnose serial '" + io::Printable(s.substr(0, 20)) + "'", [s](Stub* st) {
      grpc::ClientContext c; v1::DiagnoseRequest q; q.set_serial(s); v1::DiagnoseResponse r; return st->Diagnose(&c, q, &r);
    });
  }
  add("Diagnose without a recording", [](Stub* st) {
    grpc::ClientContext c; v1::DiagnoseRequest q; q.set_serial("IPM-GOOD"); v1::DiagnoseResponse r;
    return st->Diagnose(&c, q, &r);
  });

  // --- ListMotors.
  for (int size : {-1, 1001, -2147483647}) {
    add("ListMotors page_size " + std::to_string(size), [size](Stub* st) {
      grpc::ClientContext c; v1::ListMotorsRequest q; q.set_page_size(size); v1::ListMotorsResponse r;
      return st->ListMotors(&c, q, &r);
    });
  }
  for (const std::string& tok : std::vector<std::string>{"3abc", "-1", "x", "99999999999", " 3", "3 ", "0x10", "+5"}) {
    add("ListMotors page_token '" + tok + "'", [tok](Stub* st) {
      grpc::ClientContext c; v1::ListMotorsRequest q; q.set_page_token(tok); v1::ListMotorsResponse r;
      return st->ListMotors(&c, q, &r);
    });
  }
  add("ListMotors prefix 1 MB", [](Stub* st) {
    grpc::ClientContext c; v1::ListMotorsRequest q; q.set_serial_prefix(std::string(1 << 20, 'I'));
    v1::ListMotorsResponse r; return st->ListMotors(&c, q, &r);
  });

  // --- QueryFlux.
  auto query = [](int version, std::vector<std::pair<double, double>> pts) {
    return [=](Stub* st) {
      grpc::ClientContext c;
      v1::QueryFluxRequest q;
      q.set_serial("IPM-GOOD"); q.set_version(version);
      for (auto [d, qq] : pts) { auto* p = q.add_points(); p->set_id_a(d); p->set_iq_a(qq); }
      v1::QueryFluxResponse r;
      return st->QueryFlux(&c, q, &r);
    };
  };
  add("QueryFlux version -1", query(-1, {{-20, 40}}));
  add("QueryFlux version 999", query(999, {{-20, 40}}));
  for (double v : {kNaN, kInf, -kInf, 1e5, -1e300}) {
    add("QueryFlux id_a " + std::to_string(v), query(0, {{v, 40}}));
    add("QueryFlux iq_a " + std::to_string(v), query(0, {{-20, v}}));
  }
  add("QueryFlux too many points", query(0, std::vector<std::pair<double, double>>(kMaxQueryPoints + 1, {-20, 40})));

  // --- ExportTable.
  auto exp = [](std::function<void(v1::ExportTableRequest*)> set) {
    return AboutGoodSerial(&Stub::ExportTable, std::move(set));
  };
  add("ExportTable points 1", exp([](auto* q) { q->set_points(1); }));
  add("ExportTable points 5000", exp([](auto* q) { q->set_points(5000); }));
  add("ExportTable points -3", exp([](auto* q) { q->set_points(-3); }));
  add("ExportTable speed_points 1", exp([](auto* q) { q->set_table("fw"); q->set_speed_points(1); }));
  add("ExportTable speed_points 10000", exp([](auto* q) { q->set_table("fw"); q->set_speed_points(10000); }));
  add("ExportTable fw 1024 x 256", exp([](auto* q) { q->set_table("fw"); q->set_points(1024); q->set_speed_points(256); }));
  for (double v : {-1.0, kNaN, kInf, 1e9}) {
    add("ExportTable speed_max_rpm " + std::to_string(v), exp([v](auto* q) { q->set_speed_max_rpm(v); }));
    add("ExportTable i_max_a " + std::to_string(v), exp([v](auto* q) { q->set_i_max_a(v); }));
    add("ExportTable udc_v " + std::to_string(v), exp([v](auto* q) { q->set_udc_v(v); }));
  }
  add("ExportTable table xyz", exp([](auto* q) { q->set_table("xyz"); }));
  add("ExportTable generating fw", exp([](auto* q) { q->set_table("fw"); q->set_generating(true); }));
  add("ExportTable generating mtpa", exp([](auto* q) { q->set_generating(true); }));
  for (double v : {-1.0, 0.0, kNaN, kInf, -kInf, 1e9, -1e-300}) {
    add("ExportTable udc_axis_v " + std::to_string(v),
        exp([v](auto* q) { q->set_table("envelope"); q->add_udc_axis_v(40); q->add_udc_axis_v(v); }));
  }
  add("ExportTable udc_axis_v 33 voltages", exp([](auto* q) {
        q->set_table("envelope");
        for (int k = 0; k < 33; ++k) q->add_udc_axis_v(40 + k);
      }));
  add("ExportTable udc_axis_v 100000 voltages", exp([](auto* q) {
        for (int k = 0; k < 100000; ++k) q->add_udc_axis_v(40 + k);
      }));
  add("ExportTable udc_axis_v decreasing", exp([](auto* q) { q->set_table("envelope"); q->add_udc_axis_v(60); q->add_udc_axis_v(40); }));
  add("ExportTable udc_axis_v same label", exp([](auto* q) { q->set_table("envelope"); q->add_udc_axis_v(40); q->add_udc_axis_v(40.0000001); }));
  add("ExportTable udc_axis_v with udc_v", exp([](auto* q) { q->set_table("envelope"); q->add_udc_axis_v(40); q->set_udc_v(50); }));
  add("ExportTable udc_axis_v fw too many cells", exp([](auto* q) {
        q->set_table("fw"); q->set_points(1024); q->set_speed_points(64); q->add_udc_axis_v(40); q->add_udc_axis_v(50);
      }));
  add("ExportTable format exe", exp([](auto* q) { q->set_format("exe"); }));
  add("ExportTable version -1", exp([](auto* q) { q->set_version(-1); }));
  add("ExportTable version 999", exp([](auto* q) { q->set_version(999); }));
  add("ExportTable unknown serial", exp([](auto* q) { q->set_serial("IPM-NOPE"); }));

  // --- FleetStatistics.
  auto fleet = [](double sigma, std::vector<std::pair<double, double>> pts) {
    return [=](Stub* st) {
      grpc::ClientContext c;
      v1::FleetStatisticsRequest q;
      q.set_outlier_sigma(sigma);
      for (auto [d, qq] : pts) { auto* p = q.add_points(); p->set_id_a(d); p->set_iq_a(qq); }
      v1::FleetStatisticsResponse r;
      return st->FleetStatistics(&c, q, &r);
    };
  };
  for (double s : {-1.0, kNaN, kInf, 1e9}) add("FleetStatistics outlier_sigma " + std::to_string(s), fleet(s, {}));
  add("FleetStatistics too many points", fleet(0, std::vector<std::pair<double, double>>(kMaxFleetPoints + 1, {-20, 40})));
  add("FleetStatistics id_a NaN", fleet(0, {{kNaN, 40}}));
  add("FleetStatistics iq_a 1e300", fleet(0, {{-20, 1e300}}));

  // --- GetReport.
  auto report = [](std::function<void(v1::GetReportRequest*)> set) {
    return AboutGoodSerial(&Stub::GetReport, std::move(set));
  };
  for (const auto& s : bad_serials) {
    add("GetReport serial '" + io::Printable(s.substr(0, 20)) + "'", report([s](auto* q) { q->set_serial(s); }));
  }
  add("GetReport unknown serial", report([](auto* q) { q->set_serial("IPM-NOPE"); }));
  for (int v : {-1, -2147483647, 999}) {
    add("GetReport version " + std::to_string(v), report([v](auto* q) { q->set_version(v); }));
  }
  for (double v : {-1.0, kNaN, kInf, -kInf, 1e9, -1e-300}) {
    add("GetReport speed_rpm " + std::to_string(v), report([v](auto* q) { q->set_speed_rpm(v); }));
    add("GetReport udc_v " + std::to_string(v), report([v](auto* q) { q->set_udc_v(v); }));
  }
  return cs;
}

TEST_F(BadInput, NoneIsAcceptedSilently) {
  const auto cases = Cases();
  ASSERT_GE(cases.size(), 150u);
  size_t refused = 0;
  for (const auto& c : cases) {
    const grpc::Status s = c.run(stub_);
    EXPECT_FALSE(s.ok()) << c.name << ": accepted";
    if (s.ok()) continue;
    ++refused;
    EXPECT_NE(s.error_code(), grpc::StatusCode::INTERNAL) << c.name << ": " << s.error_message();
    EXPECT_NE(s.error_code(), grpc::StatusCode::UNKNOWN) << c.name << ": " << s.error_message();
    EXPECT_FALSE(s.error_message().empty()) << c.name;
    EXPECT_LE(s.error_message().size(), kMaxStatusMessageBytes) << c.name;
    EXPECT_EQ(io::Printable(s.error_message()), s.error_message()) << c.name;
  }
  std::printf("bad-input suite: %zu cases, %zu refused\n", cases.size(), refused);
  // The good motor is untouched: still one calibration, version 1.
  auto cal = store_->GetCalibration("IPM-GOOD", 0);
  ASSERT_TRUE(cal.ok());
  EXPECT_EQ(cal->version, 1);
}

}  // namespace
}  // namespace fluxcal::server
