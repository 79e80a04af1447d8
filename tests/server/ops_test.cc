// Service limits and operations: per-identity limits on open calls and on
// request bytes in flight (RESOURCE_EXHAUSTED, given back when calls end),
// unauthenticated calls refused before their body is read (measured at a
// counting TCP proxy in front of the server), revocation without restart
// (a changed keys file, SIGHUP on a real `fluxcal serve` that stays alive,
// a broken file that keeps the keys before), the health role, the keys
// file's group and mode, and the CLI refusing to send a token in clear.
#include <arpa/inet.h>
#include <grp.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "gtest/gtest.h"
#include "io/csv.h"
#include "io/sha256.h"
#include "server/auth.h"
#include "server/bearer.h"
#include "tests/server/authorized_server.h"
#include "tests/server/test_support.h"
#include "server/limits.h"
#include "server/service.h"
#include "storage/store.h"

namespace fluxcal::server {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string TempPath(const std::string& name) {
  return (fs::temp_directory_path() / ("fluxcal_ops_" + std::to_string(::getpid()) + "_" + name)).string();
}

std::unique_ptr<v1::CalibrationService::Stub> Stub(const std::string& addr, const std::string& token,
                                                   int max_send_bytes = -1) {
  grpc::ChannelArguments args;
  args.SetMaxSendMessageSize(max_send_bytes);
  return v1::CalibrationService::NewStub(
      BearerChannel(addr, grpc::InsecureChannelCredentials(), TokenOrNone(token), args));
}

// A server with identities (two stations, an engineer, a health check) on
// loopback, with the given limits.
struct Fixture : test_support::AuthorizedServer {
  std::map<std::string, std::string> tokens;   // by identity name

  Fixture(const std::string& name, IdentityLimits limits) {
    Keys keys;
    for (auto [who, role] : {std::pair{"station-1", Role::kStation}, {"station-2", Role::kStation},
                             {"engineer-1", Role::kEngineer}, {"health-1", Role::kHealth}}) {
      tokens[who] = *NewToken();
      keys.entries.push_back({who, role, io::Sha256Hex(tokens[who]), ""});
    }
    Start(TempPath(name + ".db"), keys, ServerOptions{}, &limits);
  }
  // Waits (at most 20 s) until `who` has `streams` calls open on the server.
  bool WaitForStreams(const std::string& who, int streams) const {
    const auto until = Clock::now() + std::chrono::seconds(20);
    while (service->limiter().UsageOf(who).streams != streams) {
      if (Clock::now() > until) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return true;
  }
};

v1::RecordingChunk Chunk(const std::string& serial, int k, size_t bytes) {
  v1::RecordingChunk c;
  if (k == 0) c.set_serial(serial);
  c.set_path("points/p" + std::to_string(k) + ".csv");
  c.set_data(std::string(bytes, 'x'));
  return c;
}

TEST(Limits, OpenCallsPerIdentityAreBounded) {
  IdentityLimits lim;
  lim.max_streams = 2;
  Fixture f("streams", lim);
  auto st1 = Stub(f.addr(), f.tokens["station-1"]);
  // Two streams of station-1 held open.
  grpc::ClientContext c1, c2;
  v1::IngestRecordingResponse r1, r2;
  auto w1 = st1->IngestRecording(&c1, &r1);
  auto w2 = st1->IngestRecording(&c2, &r2);
  ASSERT_TRUE(w1->Write(Chunk("IPM-LIM-1", 0, 10)));
  ASSERT_TRUE(w2->Write(Chunk("IPM-LIM-2", 0, 10)));
  ASSERT_TRUE(f.WaitForStreams("station-1", 2)) << "expected 2 open calls of station-1 on the server, got "
                                                << f.service->limiter().UsageOf("station-1").streams;
  // A third call of the same identity, of any kind, is refused ...
  {
    grpc::ClientContext c;
    v1::FitRequest q;
    q.set_serial("IPM-LIM-1");
    v1::FitResponse r;
    const grpc::Status s = st1->Fit(&c, q, &r);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << "expected RESOURCE_EXHAUSTED, got "
                                                                    << s.error_code() << ": " << s.error_message();
    EXPECT_NE(s.error_message().find("--max-streams-per-identity"), std::string::npos) << s.error_message();
    EXPECT_NE(s.error_message().find("'station-1' has 2 calls open"), std::string::npos) << s.error_message();
  }
  // ... another identity is not affected ...
  {
    auto st2 = Stub(f.addr(), f.tokens["station-2"]);
    grpc::ClientContext c;
    v1::FitRequest q;
    q.set_serial("IPM-NONE");
    v1::FitResponse r;
    EXPECT_EQ(st2->Fit(&c, q, &r).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  // ... and once the two end, station-1 calls again.
  for (auto* w : {w1.get(), w2.get()}) {
    w->WritesDone();
    EXPECT_EQ(w->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);   // junk, not a recording set
  }
  ASSERT_TRUE(f.WaitForStreams("station-1", 0));
  grpc::ClientContext c;
  v1::FitRequest q;
  q.set_serial("IPM-NONE");
  v1::FitResponse r;
  EXPECT_EQ(st1->Fit(&c, q, &r).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST(Limits, RequestBytesInFlightPerIdentityAreBounded) {
  IdentityLimits lim;
  lim.max_inflight_bytes = 1 << 20;
  Fixture f("bytes", lim);
  auto st1 = Stub(f.addr(), f.tokens["station-1"]);
  constexpr size_t kChunk = 256 << 10;
  // Stream A holds 3 x 256 KiB and stays open.
  grpc::ClientContext ca;
  v1::IngestRecordingResponse ra;
  auto wa = st1->IngestRecording(&ca, &ra);
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(wa->Write(Chunk("IPM-BYTES-A", k, kChunk)));
  const auto until = Clock::now() + std::chrono::seconds(20);
  while (f.service->limiter().UsageOf("station-1").bytes < int64_t{3 * kChunk} && Clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_GE(f.service->limiter().UsageOf("station-1").bytes, int64_t{3 * kChunk});
  // Stream B of the same identity passes 1 MiB with its second chunk.
  {
    grpc::ClientContext cb;
    v1::IngestRecordingResponse rb;
    auto wb = st1->IngestRecording(&cb, &rb);
    for (int k = 0; k < 2 && wb->Write(Chunk("IPM-BYTES-B", k, kChunk)); ++k) {
    }
    wb->WritesDone();
    const grpc::Status s = wb->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
        << "expected RESOURCE_EXHAUSTED, got " << s.error_code() << ": " << s.error_message();
    EXPECT_NE(s.error_message().find("--max-inflight-bytes-per-identity"), std::string::npos) << s.error_message();
  }
  // Another station uploads the same meanwhile.
  {
    auto st2 = Stub(f.addr(), f.tokens["station-2"]);
    grpc::ClientContext cb;
    v1::IngestRecordingResponse rb;
    auto wb = st2->IngestRecording(&cb, &rb);
    for (int k = 0; k < 2; ++k) ASSERT_TRUE(wb->Write(Chunk("IPM-BYTES-C", k, kChunk)));
    wb->WritesDone();
    EXPECT_EQ(wb->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);   // reached validation
  }
  wa->WritesDone();
  EXPECT_EQ(wa->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  // Everything given back when the calls ended: station-1 uploads again.
  ASSERT_TRUE(f.WaitForStreams("station-1", 0));
  EXPECT_EQ(f.service->limiter().UsageOf("station-1").bytes, 0);
  grpc::ClientContext cb;
  v1::IngestRecordingResponse rb;
  auto wb = st1->IngestRecording(&cb, &rb);
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(wb->Write(Chunk("IPM-BYTES-D", k, kChunk)));
  wb->WritesDone();
  EXPECT_EQ(wb->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST(Limits, AMessageAboveTheServiceLimitIsRefused) {
  Fixture f("msg", IdentityLimits{});
  auto st1 = Stub(f.addr(), f.tokens["station-1"]);
  grpc::ClientContext c;
  v1::IngestRecordingResponse r;
  auto w = st1->IngestRecording(&c, &r);
  w->Write(Chunk("IPM-BIG", 0, kMaxMessageBytes + 1));
  w->WritesDone();
  const grpc::Status s = w->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
}

// Forwards TCP connections to a server and counts the bytes clients send.
class CountingProxy {
 public:
  explicit CountingProxy(int upstream_port) : upstream_port_(upstream_port) {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof a;
    ok_ = ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), len) == 0 && ::listen(listen_fd_, 8) == 0 &&
          ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) == 0;
    port_ = ntohs(a.sin_port);
    acceptor_ = std::thread([this] { Accept(); });
  }
  ~CountingProxy() {
    stop_ = true;
    acceptor_.join();
    {
      std::lock_guard<std::mutex> l(mu_);
      for (int fd : fds_) ::shutdown(fd, SHUT_RDWR);
    }
    for (auto& t : pumps_) t.join();
    for (int fd : fds_) ::close(fd);
    ::close(listen_fd_);
  }
  bool ok() const { return ok_; }
  int port() const { return port_; }
  int64_t client_bytes() const { return client_bytes_.load(); }

 private:
  void Accept() {
    while (!stop_) {
      pollfd p{listen_fd_, POLLIN, 0};
      if (::poll(&p, 1, 50) <= 0) continue;
      const int c = ::accept(listen_fd_, nullptr, nullptr);
      if (c < 0) continue;
      const int s = ::socket(AF_INET, SOCK_STREAM, 0);
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      a.sin_port = htons(static_cast<uint16_t>(upstream_port_));
      if (::connect(s, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(c);
        ::close(s);
        continue;
      }
      std::lock_guard<std::mutex> l(mu_);
      fds_.push_back(c);
      fds_.push_back(s);
      pumps_.emplace_back([this, c, s] { Pump(c, s, &client_bytes_); });
      pumps_.emplace_back([this, c, s] { Pump(s, c, nullptr); });
    }
  }
  static void Pump(int from, int to, std::atomic<int64_t>* count) {
    char buf[16384];
    while (true) {
      const ssize_t n = ::read(from, buf, sizeof buf);
      if (n <= 0) break;
      if (count) *count += n;
      for (ssize_t off = 0; off < n;) {
        const ssize_t w = ::write(to, buf + off, static_cast<size_t>(n - off));
        if (w <= 0) return;
        off += w;
      }
    }
    ::shutdown(to, SHUT_WR);
  }

  int upstream_port_, listen_fd_ = -1, port_ = 0;
  bool ok_ = false;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> client_bytes_{0};
  std::thread acceptor_;
  std::mutex mu_;
  std::vector<int> fds_;
  std::vector<std::thread> pumps_;
};

// A QueryFlux of `points` points: ~20 bytes each on the wire.
v1::QueryFluxRequest BigQuery(int points) {
  v1::QueryFluxRequest q;
  q.set_serial("IPM-BIG");
  for (int k = 0; k < points; ++k) {
    auto* p = q.add_points();
    p->set_id_a(-1.0 - k);
    p->set_iq_a(1.0 + k);
  }
  return q;
}

// The reported defect: a 64 MiB message was read before the caller was
// known. Now a call without a valid credential ends after its headers: the
// server takes what HTTP/2 flow control lets the client send ahead (the
// stream's window), not the message.
TEST(PreAuth, AnUnauthenticatedLargeMessageIsRefusedUnread) {
  Fixture f("preauth", IdentityLimits{});
  const v1::QueryFluxRequest q = BigQuery(160000);   // 3.2 MB, under the 4 MiB message limit
  const int64_t message_bytes = static_cast<int64_t>(q.ByteSizeLong());
  ASSERT_GT(message_bytes, 3000000);
  ASSERT_LT(message_bytes, kMaxMessageBytes);
  // One call on a fresh connection through a fresh proxy; the bytes the
  // client got to send, counted once the connection has gone quiet.
  auto measure = [&](const std::string& token, grpc::StatusCode* code, std::string* message) {
    CountingProxy proxy(f.port);
    EXPECT_TRUE(proxy.ok());
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);   // a connection of its own
    auto stub = v1::CalibrationService::NewStub(BearerChannel(
        "127.0.0.1:" + std::to_string(proxy.port()), grpc::InsecureChannelCredentials(), TokenOrNone(token), args));
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    v1::QueryFluxResponse r;
    const grpc::Status s = stub->QueryFlux(&c, q, &r);
    *code = s.error_code();
    *message = s.error_message();
    int64_t last = -1;
    for (int quiet = 0; quiet < 10;) {   // 10 x 20 ms without a byte more
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      const int64_t now = proxy.client_bytes();
      quiet = now == last ? quiet + 1 : 0;
      last = now;
    }
    return last;
  };
  for (const std::string& token : {std::string(), std::string("not-a-token"), std::string(64, '0')}) {
    for (int attempt = 0; attempt < 3; ++attempt) {
      grpc::StatusCode code;
      std::string message;
      const int64_t sent = measure(token, &code, &message);
      EXPECT_EQ(code, grpc::StatusCode::UNAUTHENTICATED) << message;
      // Expected: at most what flow control lets a client send ahead of the
      // server (64 KiB per stream; allow 256 KiB), not the 3.2 MB message.
      EXPECT_LT(sent, int64_t{256} << 10) << "token '" << token << "': the server took " << sent
                                          << " bytes of a " << message_bytes << "-byte unauthenticated message";
      std::printf("[ measured ] unauthenticated %lld-byte QueryFlux (token '%s'): %lld bytes reached the server\n",
                  static_cast<long long>(message_bytes), token.substr(0, 12).c_str(), static_cast<long long>(sent));
    }
  }
  // An identity without the right is refused before the body as well.
  {
    grpc::StatusCode code;
    std::string message;
    EXPECT_LT(measure(f.tokens["health-1"], &code, &message), int64_t{256} << 10);
    EXPECT_EQ(code, grpc::StatusCode::PERMISSION_DENIED) << message;
  }
  // The same message from an engineer passes the proxy whole (the
  // measurement sees big messages) and reaches the handler's own limit.
  {
    grpc::StatusCode code;
    std::string message;
    EXPECT_GE(measure(f.tokens["engineer-1"], &code, &message), message_bytes);
    EXPECT_EQ(code, grpc::StatusCode::RESOURCE_EXHAUSTED) << message;
    EXPECT_NE(message.find("points: at most 100000"), std::string::npos) << message;
  }
}

// Revocation without a restart, in process: the file changes, the next
// call sees it (check interval 0 here; 1 s in `fluxcal serve`).
TEST(Revocation, AChangedKeysFileTakesEffectAndABrokenOneKeepsTheKeys) {
  const std::string keys_path = TempPath("reload-keys.json");
  Keys keys;
  const std::string t1 = *NewToken(), t2 = *NewToken();
  keys.entries.push_back({"eng-1", Role::kEngineer, io::Sha256Hex(t1), ""});
  keys.entries.push_back({"eng-2", Role::kEngineer, io::Sha256Hex(t2), ""});
  ASSERT_TRUE(SaveKeys(keys_path, keys).ok());
  std::vector<std::string> log;
  std::mutex log_mu;
  auto auth = Authorizer::FromFile(keys_path, [&](const std::string& m) {
    std::lock_guard<std::mutex> l(log_mu);
    log.push_back(m);
  });
  ASSERT_TRUE(auth.ok()) << auth.status();
  (*auth)->set_check_interval(std::chrono::milliseconds(0));
  const std::string db = TempPath("reload.db");
  for (auto sfx : {"", "-wal", "-shm"}) fs::remove(db + sfx);
  auto store = std::move(*storage::Store::Open(db));
  CalibrationServiceImpl service(store.get());
  service.set_authorizer(auth->get());
  ServerOptions opt;
  opt.authorizer = auth->get();
  int port = 0;
  auto server = StartServer(&service, "127.0.0.1:0", &port, opt);
  const std::string addr = "127.0.0.1:" + std::to_string(port);
  auto list = [&](const std::string& token) {
    grpc::ClientContext c;
    v1::ListMotorsRequest q;
    v1::ListMotorsResponse r;
    return Stub(addr, token)->ListMotors(&c, q, &r).error_code();
  };
  EXPECT_EQ(list(t1), grpc::StatusCode::OK);
  // Revoke eng-1 the way `fluxcal admin revoke` does.
  keys.entries.erase(keys.entries.begin());
  ASSERT_TRUE(SaveKeys(keys_path, keys).ok());
  EXPECT_EQ(list(t1), grpc::StatusCode::UNAUTHENTICATED) << "a revoked token must fail on its next call";
  EXPECT_EQ(list(t2), grpc::StatusCode::OK);
  // A broken file keeps the keys in force and says why.
  std::ofstream(keys_path) << "{\"format\": \"fluxcal.keys.v1\", \"keys\": [ {\"name\": ";
  EXPECT_EQ(list(t2), grpc::StatusCode::OK) << "a broken keys file must not drop the keys in force";
  EXPECT_EQ(list(t1), grpc::StatusCode::UNAUTHENTICATED) << "a broken keys file must not bring back old ones";
  EXPECT_EQ(list(""), grpc::StatusCode::UNAUTHENTICATED) << "a broken keys file must never open the service";
  {
    std::lock_guard<std::mutex> l(log_mu);
    ASSERT_FALSE(log.empty());
    EXPECT_NE(log.back().find("not reloaded"), std::string::npos) << log.back();
    EXPECT_NE(log.back().find("keeping the 1 identities loaded before"), std::string::npos) << log.back();
  }
  // Reload() reports the error too.
  EXPECT_FALSE((*auth)->Reload().ok());
  server->Shutdown();
  store.reset();
  for (auto sfx : {"", "-wal", "-shm"}) fs::remove(db + sfx);
  fs::remove(keys_path);
}

std::string ReadAll(const std::string& path) { return io::ReadFileToString(path).value_or(""); }

// Waits (at most 20 s) until `path` contains `what` after `from`.
bool WaitForText(const std::string& path, const std::string& what, size_t from = 0) {
  const auto until = Clock::now() + std::chrono::seconds(20);
  while (Clock::now() < until) {
    const std::string t = ReadAll(path);
    if (t.size() > from && t.find(what, from) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

int RunFluxcal(const std::string& args, std::string* err, const std::string& env = "") {
  const std::string out = TempPath("cli.err");
  const int rc = std::system((env + " " + FLUXCAL_BINARY + " " + args + " 2>" + out + " >/dev/null").c_str());
  *err = ReadAll(out);
  fs::remove(out);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// The reported defect: SIGHUP killed `fluxcal serve`, and a revoked token
// worked until a restart.
TEST(Revocation, SighupReloadsTheKeysOfARunningServeWhichStaysUp) {
  const std::string dir = TempPath("hup");
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string keys = dir + "/keys.json", err_path = dir + "/serve.err";
  std::string err;
  ASSERT_EQ(RunFluxcal("admin add-key --keys " + keys + " --name eng-1 --role engineer --json", &err), 0) << err;
  ASSERT_EQ(RunFluxcal("admin add-key --keys " + keys + " --name eng-2 --role engineer --json", &err), 0) << err;
  // The tokens: add-key prints them once; make two more we know.
  Keys k = *LoadKeys(keys);
  const std::string t1 = *NewToken(), t2 = *NewToken();
  k.entries[0].token_sha256 = io::Sha256Hex(t1);
  k.entries[1].token_sha256 = io::Sha256Hex(t2);
  ASSERT_TRUE(SaveKeys(keys, k).ok());
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    std::freopen(err_path.c_str(), "w", stderr);
    execl(FLUXCAL_BINARY, FLUXCAL_BINARY, "serve", "--db", (dir + "/s.db").c_str(), "--listen", "127.0.0.1:0",
          "--auth", keys.c_str(), nullptr);
    _exit(127);
  }
  ASSERT_TRUE(WaitForText(err_path, "listening on")) << ReadAll(err_path);
  const std::string text = ReadAll(err_path);
  const auto at = text.find("(port ");
  ASSERT_NE(at, std::string::npos) << text;
  const std::string addr = "127.0.0.1:" + std::to_string(std::atoi(text.c_str() + at + 6));
  auto list = [&](const std::string& token) {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    v1::ListMotorsRequest q;
    v1::ListMotorsResponse r;
    return Stub(addr, token)->ListMotors(&c, q, &r).error_code();
  };
  auto alive = [&] { return ::waitpid(pid, nullptr, WNOHANG) == 0; };
  EXPECT_EQ(list(t1), grpc::StatusCode::OK);
  // Revoke eng-1 with the CLI, then SIGHUP: the next call fails.
  ASSERT_EQ(RunFluxcal("admin revoke --keys " + keys + " --name eng-1", &err), 0) << err;
  size_t mark = ReadAll(err_path).size();
  ASSERT_EQ(::kill(pid, SIGHUP), 0);
  EXPECT_TRUE(WaitForText(err_path, "keys reloaded from", mark)) << ReadAll(err_path);
  EXPECT_TRUE(alive()) << "SIGHUP must not end the server";
  EXPECT_EQ(list(t1), grpc::StatusCode::UNAUTHENTICATED) << "revoked eng-1 still answered after SIGHUP";
  EXPECT_EQ(list(t2), grpc::StatusCode::OK);
  // A broken keys file on SIGHUP: logged, the keys before stay, still up.
  std::ofstream(keys) << "not json";
  mark = ReadAll(err_path).size();
  ASSERT_EQ(::kill(pid, SIGHUP), 0);
  EXPECT_TRUE(WaitForText(err_path, "not reloaded", mark)) << ReadAll(err_path);
  EXPECT_TRUE(alive());
  EXPECT_EQ(list(t2), grpc::StatusCode::OK);
  EXPECT_EQ(list(t1), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(list(""), grpc::StatusCode::UNAUTHENTICATED);
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "serve should exit 0 on SIGTERM";
  fs::remove_all(dir);
}

TEST(Roles, AHealthIdentityProvesTheDatabaseAnswersAndSeesNoData) {
  Fixture f("health", IdentityLimits{});
  {
    auto st = Stub(f.addr(), f.tokens["station-1"]);
    grpc::ClientContext c;
    ASSERT_TRUE(test_support::IngestSmallGrid(st.get(), &c, "IPM-HEALTH-1").ok());
  }
  auto list = [&](const std::string& who, v1::ListMotorsResponse* r) {
    grpc::ClientContext c;
    v1::ListMotorsRequest q;
    return Stub(f.addr(), f.tokens[who])->ListMotors(&c, q, r);
  };
  v1::ListMotorsResponse eng, health;
  ASSERT_TRUE(list("engineer-1", &eng).ok());
  EXPECT_EQ(eng.motors_size(), 1);
  ASSERT_TRUE(list("health-1", &health).ok());
  EXPECT_EQ(health.motors_size(), 0) << "a health identity must see no serials";
  for (Rpc rpc : kAllRpcs) EXPECT_EQ(RoleMayCall(Role::kHealth, rpc), rpc == Rpc::kListMotors) << RpcName(rpc);
}

TEST(Keys, TheFileIsReadableByTheServiceGroupAndStaysSoWhenReplaced) {
  const std::string path = TempPath("group-keys.json");
  fs::remove(path);
  Keys keys;
  keys.entries.push_back({"eng-1", Role::kEngineer, io::Sha256Hex("x"), ""});
  // New: owner only.
  ASSERT_TRUE(SaveKeys(path, keys).ok());
  struct stat st;
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  // A group that is not ours needs root to give.
  if (::geteuid() != 0) GTEST_SKIP() << "needs root to give the file another group (chown)";
  const gid_t service_gid = 1;   // "daemon" on Debian; any group not root's
  ASSERT_TRUE(SaveKeys(path, keys, std::to_string(service_gid)).ok());
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0640u);
  EXPECT_EQ(st.st_gid, service_gid);
  // Replaced (a revoke, an add-key without --group): same group and mode.
  const ino_t before = st.st_ino;
  std::string err;
  ASSERT_EQ(RunFluxcal("admin revoke --keys " + path + " --name eng-1", &err), 0) << err;
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_NE(st.st_ino, before) << "expected an atomic replacement (a new inode)";
  EXPECT_EQ(st.st_mode & 0777, 0640u) << "expected mode 0640 kept, got " << std::oct << (st.st_mode & 0777);
  EXPECT_EQ(st.st_gid, service_gid);
  // A file others could read is tightened on the next write.
  ASSERT_EQ(::chmod(path.c_str(), 0644), 0);
  ASSERT_EQ(RunFluxcal("admin add-key --keys " + path + " --name eng-3 --role engineer", &err), 0) << err;
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0640u);
  // --group with a group that does not exist names it.
  EXPECT_EQ(RunFluxcal("admin revoke --keys " + path + " --name eng-3 --group no-such-group-xyz", &err), 1);
  EXPECT_NE(err.find("group 'no-such-group-xyz': no such group"), std::string::npos) << err;
  fs::remove(path);
}

// The reported defect: the CLI sent a token in clear to any address with
// --insecure, and to a name spelt like 127.x.
TEST(Cli, ATokenIsNeverSentInClearOffLoopback) {
  const std::string token = TempPath("token");
  std::ofstream(token) << std::string(64, 'a') << "\n";
  std::string err;
  // --insecure to another host: refused before connecting.
  EXPECT_EQ(RunFluxcal("list --server 10.255.0.1:1 --insecure --token-file " + token, &err), 1);
  EXPECT_NE(err.find("tokens need TLS off loopback"), std::string::npos) << err;
  EXPECT_EQ(RunFluxcal("list --server 10.255.0.1:1 --insecure", &err, "FLUXCAL_TOKEN_FILE=" + token), 1);
  EXPECT_NE(err.find("tokens need TLS off loopback"), std::string::npos) << err;
  // A name spelt like loopback that does not resolve to it: TLS, so the
  // token cannot go in clear (the connection fails on the name here).
  EXPECT_EQ(RunFluxcal("list --server 127.plant.example:1 --token-file " + token, &err), 1);
  EXPECT_EQ(err.find("tokens need TLS off loopback"), std::string::npos) << err;
  EXPECT_NE(err.find("UNAVAILABLE"), std::string::npos) << err;
  // --insecure with the name: refused like any non-loopback address.
  EXPECT_EQ(RunFluxcal("list --server 127.plant.example:1 --insecure --token-file " + token, &err), 1);
  EXPECT_NE(err.find("tokens need TLS off loopback"), std::string::npos) << err;
  fs::remove(token);
}

}  // namespace
}  // namespace fluxcal::server
