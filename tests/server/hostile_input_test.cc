// Hostile recordings: the file-write reproduction (a file name with newlines
// and an absolute path, then Diagnose), stored archives crafted in the old
// text format, limits on files and names, and the archive codec itself.
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <grpcpp/grpcpp.h>

#include "gtest/gtest.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "pipeline/recording_archive.h"
#include "server/service.h"
#include "server/validation.h"
#include "simulation/twin.h"
#include "storage/store.h"
#include "io/sha256.h"
#include "tests/server/test_support.h"
#include "absl/strings/str_cat.h"

namespace fluxcal::server {
namespace {

using pipeline::DecodeRecordingArchive;
using pipeline::Deflate;
using pipeline::EncodeRecordingArchive;
using pipeline::Inflate;

namespace fs = std::filesystem;

std::string TempPath(const std::string& name) {
  return (fs::temp_directory_path() / ("fluxcal_hostile_" + std::to_string(::getpid()) + "_" + name)).string();
}

// Every file of a small simulated set, by relative name.
io::RecordingFiles SmallSetFiles(const std::string& serial) {
  return test_support::TwinSetFiles(serial, 0.02, TempPath("set_" + serial));
}

size_t CountTempDirs(const std::string& prefix) {
  size_t n = 0;
  for (const auto& e : fs::directory_iterator(fs::temp_directory_path())) {
    if (e.path().filename().string().rfind(prefix, 0) == 0) ++n;
  }
  return n;
}

class HostileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    db_ = TempPath(::testing::UnitTest::GetInstance()->current_test_info()->name() + std::string(".db"));
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(db_ + sfx);
    int port = 0;
    ASSERT_TRUE(test_support::ServeStore(db_, &store_, &service_, &server_, &port));
    stub_ = v1::CalibrationService::NewStub(
        grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials()));
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
    store_.reset();
    for (auto sfx : {"", "-wal", "-shm"}) fs::remove(db_ + sfx);
  }
  grpc::Status Upload(const std::string& serial, const std::string& station, const io::RecordingFiles& files,
                      v1::IngestRecordingResponse* resp) {
    return test_support::UploadRecording(stub_.get(), serial, station, files, resp);
  }
  grpc::Status DiagnoseSerial(const std::string& serial) {
    grpc::ClientContext ctx;
    v1::DiagnoseRequest req;
    req.set_serial(serial);
    v1::DiagnoseResponse resp;
    return stub_->Diagnose(&ctx, req, &resp);
  }

  std::string db_;
  std::unique_ptr<storage::Store> store_;
  std::unique_ptr<CalibrationServiceImpl> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<v1::CalibrationService::Stub> stub_;
};

// The reported attack: a name that, in the old "path\nsize\ndata" archive,
// smuggled a second record with an absolute path. It must be refused at
// ingest, naming the file, and nothing may be written anywhere.
TEST_F(HostileTest, FileWriteReproductionIsRefusedAtIngest) {
  const std::string target = TempPath("pwned.db");
  fs::remove(target);
  auto files = SmallSetFiles("IPM-HOST-1");
  files["x\n7\npayload\n" + target] = "overwritten";
  const size_t diag_dirs = CountTempDirs("fluxcal-diag-");
  const size_t ingest_dirs = CountTempDirs("fluxcal-ingest-");
  v1::IngestRecordingResponse resp;
  const grpc::Status s = Upload("IPM-HOST-1", "st-1", files, &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_NE(s.error_message().find(".path: file 'x\\x0a7\\x0apayload\\x0a/"), std::string::npos) << s.error_message();
  EXPECT_EQ(DiagnoseSerial("IPM-HOST-1").error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_FALSE(fs::exists(target));
  EXPECT_EQ(CountTempDirs("fluxcal-diag-"), diag_dirs);
  EXPECT_EQ(CountTempDirs("fluxcal-ingest-"), ingest_dirs);
}

TEST_F(HostileTest, IllegalNamesAreRefusedOneByOne) {
  for (const std::string& bad : std::vector<std::string>{"/etc/passwd", "../up.csv", "points/../../x", "a//b", "./manifest.json",
                                "points/p 1.csv", std::string("nul\0byte", 8), "tab\tname", "a/b/c/d/e.csv",
                                std::string(300, 'a'), "ctrl\x7f"}) {
    auto files = SmallSetFiles("IPM-HOST-2");
    files[bad] = "x";
    v1::IngestRecordingResponse resp;
    const grpc::Status s = Upload("IPM-HOST-2", "", files, &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << io::Printable(bad);
    EXPECT_NE(s.error_message().find(".path: file '"), std::string::npos) << s.error_message();
    for (unsigned char c : s.error_message()) EXPECT_GE(c, 0x20) << "control byte in message";
  }
}

TEST_F(HostileTest, JunkFilesStationIdsAndSerialsAreRefused) {
  auto files = SmallSetFiles("IPM-HOST-3");
  v1::IngestRecordingResponse resp;
  auto junk = files;
  junk["junk.bin"] = std::string(1000, 'j');
  grpc::Status s = Upload("IPM-HOST-3", "", junk, &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("'junk.bin' is not referenced by manifest.json"), std::string::npos)
      << s.error_message();
  s = Upload("IPM-HOST-3", "station\nwith newline", files, &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("station_id: only printable ASCII"), std::string::npos) << s.error_message();
  s = Upload("IPM-HOST-3", std::string(1 << 20, 's'), files, &resp);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_LT(s.error_message().size(), 200u);
  for (const std::string& serial : std::vector<std::string>{".", "..", "a/b"}) {
    s = Upload(serial, "", files, &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << serial;
  }
  // The honest upload of the same files still works, and diagnoses.
  s = Upload("IPM-HOST-3", "st-3", files, &resp);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_TRUE(DiagnoseSerial("IPM-HOST-3").ok());
}

TEST_F(HostileTest, TooManyFilesIsResourceExhausted) {
  grpc::ClientContext ctx;
  v1::IngestRecordingResponse resp;
  auto w = stub_->IngestRecording(&ctx, &resp);
  for (int k = 0; k <= kMaxRecordingFiles; ++k) {
    v1::RecordingChunk c;
    if (k == 0) c.set_serial("IPM-HOST-4");
    c.set_path("points/f" + std::to_string(k) + ".csv");
    if (!w->Write(c)) break;
  }
  w->WritesDone();
  const grpc::Status s = w->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_NE(s.error_message().find("files"), std::string::npos);
}

// A recording stored by an earlier version in the text format, with a name
// crafted to break out: Diagnose refuses it (DATA_LOSS) and writes nothing.
TEST_F(HostileTest, LegacyArchiveWithHostileNameWritesNothing) {
  const std::string target = TempPath("legacy-pwned");
  fs::remove(target);
  auto files = SmallSetFiles("IPM-HOST-5");
  std::string legacy;
  for (const auto& [name, data] : files) absl::StrAppend(&legacy, name, "\n", data.size(), "\n", data);
  absl::StrAppend(&legacy, target, "\n5\nhello");
  auto z = Deflate(legacy);
  ASSERT_TRUE(z.ok());
  storage::MotorRow m{"IPM-HOST-5", 4, 0.01, 0.01, ""};
  storage::HfPointRow p;
  p.point_id = "p0"; p.id_a = -10; p.iq_a = 10; p.ld_h = 1e-4; p.lq_h = 2e-4; p.reliable = true;
  ASSERT_TRUE(store_->IngestHfRun(m, "legacy", "recording", {p}, io::Sha256Hex(legacy), *z,
                                  static_cast<int64_t>(legacy.size())).ok());
  const size_t diag_dirs = CountTempDirs("fluxcal-diag-");
  const grpc::Status s = DiagnoseSerial("IPM-HOST-5");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::DATA_LOSS) << s.error_message();
  EXPECT_NE(s.error_message().find("illegal file name"), std::string::npos) << s.error_message();
  EXPECT_FALSE(fs::exists(target));
  EXPECT_EQ(CountTempDirs("fluxcal-diag-"), diag_dirs);
}

TEST(RecordingArchive, RoundTripAndLegacy) {
  io::RecordingFiles files{{"manifest.json", "{}"}, {"points/p0.csv", std::string("a\0b", 3)}, {"empty.csv", ""}};
  auto back = DecodeRecordingArchive(EncodeRecordingArchive(files));
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, files);
  std::string legacy;
  for (const auto& [name, data] : files) absl::StrAppend(&legacy, name, "\n", data.size(), "\n", data);
  auto old = DecodeRecordingArchive(legacy);
  ASSERT_TRUE(old.ok()) << old.status();
  EXPECT_EQ(*old, files);
  // Malformed legacy records: size overflow, truncation, bad digits.
  for (const std::string& bad : std::vector<std::string>{"a\n99999999999999999999999\nx", "a\n10\nshort", "a\n-1\n", "a\n1x\nb", "a\nb"}) {
    auto r = DecodeRecordingArchive(bad);
    EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss) << bad;
  }
}

TEST(RecordingArchive, InflateStopsAtItsLimit) {
  const std::string big(10 << 20, 'z');   // compresses ~1000:1
  auto z = Deflate(big);
  ASSERT_TRUE(z.ok());
  EXPECT_LT(z->size(), 64u << 10);
  EXPECT_EQ(Inflate(*z, 1 << 20).status().code(), absl::StatusCode::kDataLoss);
  auto ok = Inflate(*z, big.size());
  ASSERT_TRUE(ok.ok());
  EXPECT_EQ(*ok, big);
  auto truncated = *z;
  truncated.resize(truncated.size() / 2);
  EXPECT_EQ(Inflate(truncated, big.size()).status().code(), absl::StatusCode::kDataLoss);
}

}  // namespace
}  // namespace fluxcal::server
