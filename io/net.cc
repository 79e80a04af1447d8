#include "io/net.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "io/csv.h"

namespace fluxcal::io {
namespace {

// The host of one HOST:PORT, [V6]:PORT, HOST or bare V6 item.
std::string HostOf(std::string_view item) {
  if (!item.empty() && item.front() == '[') {
    const auto close = item.find(']');
    return std::string(item.substr(1, close == std::string_view::npos ? std::string_view::npos : close - 1));
  }
  const auto colons = std::count(item.begin(), item.end(), ':');
  if (colons == 1) return std::string(item.substr(0, item.find(':')));
  return std::string(item);   // no port, or a bare IPv6 address
}

bool IsLoopbackSockaddr(const sockaddr* sa) {
  if (sa->sa_family == AF_INET) {
    // 127.0.0.0/8 (RFC 1122, 3.2.1.3 (g)).
    const auto* in = reinterpret_cast<const sockaddr_in*>(sa);
    return (ntohl(in->sin_addr.s_addr) >> 24) == 127;
  }
  if (sa->sa_family == AF_INET6) {
    // ::1 (RFC 4291, 2.5.3), and 127/8 mapped into IPv6 (::ffff:127.x.y.z).
    const auto* in6 = reinterpret_cast<const sockaddr_in6*>(sa);
    if (IN6_IS_ADDR_LOOPBACK(&in6->sin6_addr)) return true;
    return IN6_IS_ADDR_V4MAPPED(&in6->sin6_addr) && in6->sin6_addr.s6_addr[12] == 127;
  }
  return false;
}

std::string Numeric(const sockaddr* sa, socklen_t len) {
  char buf[NI_MAXHOST] = {0};
  if (getnameinfo(sa, len, buf, sizeof buf, nullptr, 0, NI_NUMERICHOST) != 0) return "?";
  return buf;
}

}  // namespace

LoopbackCheck CheckLoopback(std::string_view address) {
  LoopbackCheck out;
  for (std::string_view scheme : {"unix:", "unix-abstract:"}) {
    if (address.substr(0, scheme.size()) == scheme) {
      out.loopback = true;
      out.why = "is a unix socket";
      return out;
    }
  }
  std::vector<std::string> hosts;
  std::string_view rest = address;
  if (rest.substr(0, 5) == "ipv4:" || rest.substr(0, 5) == "ipv6:") {
    // gRPC's literal address lists: ipv4:A:P,B:P and ipv6:[A]:P,[B]:P.
    std::string_view list = rest.substr(5);
    for (size_t start = 0;;) {
      const size_t comma = list.find(',', start);
      hosts.push_back(HostOf(list.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start)));
      if (comma == std::string_view::npos) break;
      start = comma + 1;
    }
  } else {
    if (rest.substr(0, 4) == "dns:") {
      rest.remove_prefix(4);
      if (rest.substr(0, 2) == "//") {   // dns://[AUTHORITY]/HOST:PORT
        const auto slash = rest.find('/', 2);
        rest = slash == std::string_view::npos ? std::string_view() : rest.substr(slash + 1);
      }
    }
    hosts.push_back(HostOf(rest));
  }
  bool all = true;
  for (const std::string& host : hosts) {
    if (host.empty()) {
      out.why = "has no host (every interface)";
      out.loopback = false;
      return out;
    }
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* res = nullptr;
    const int rc = getaddrinfo(host.c_str(), nullptr, &hints, &res);
    if (rc != 0 || res == nullptr) {
      out.why = absl::StrCat("does not resolve ('", Printable(host), "': ", gai_strerror(rc), ")");
      out.loopback = false;
      if (res != nullptr) freeaddrinfo(res);
      return out;
    }
    for (const addrinfo* a = res; a != nullptr; a = a->ai_next) {
      const std::string n = Numeric(a->ai_addr, a->ai_addrlen);
      if (std::find(out.addresses.begin(), out.addresses.end(), n) == out.addresses.end()) out.addresses.push_back(n);
      all = all && IsLoopbackSockaddr(a->ai_addr);
    }
    freeaddrinfo(res);
  }
  out.loopback = all && !out.addresses.empty();
  out.why = absl::StrCat("resolves to ", absl::StrJoin(out.addresses, " and "));
  return out;
}

}  // namespace fluxcal::io
