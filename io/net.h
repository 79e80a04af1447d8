// Is a network address this machine only? One rule for the server (may it
// run open, without TLS?) and for the client (may it send a token in
// plaintext?): the address is loopback when it is a Unix socket, or when its
// host resolves (getaddrinfo) and EVERY address it resolves to is loopback
// (127.0.0.0/8, ::1, ::ffff:127.0.0.0/104). A name is judged by what it
// resolves to, never by how it is spelt: `127.plant.example` that does not
// resolve, or resolves to 10.20.0.5, is not loopback; `localhost` is when
// the hosts file says so.
//
// Accepted forms are the gRPC target and listen forms: HOST:PORT, HOST,
// [V6]:PORT, dns:///HOST:PORT, dns://AUTHORITY/HOST:PORT,
// ipv4:A:P[,A:P...], ipv6:[V6]:P[,...], unix:PATH, unix://PATH,
// unix-abstract:NAME. An empty host (":50051", every interface) is not
// loopback; nor is a wildcard (0.0.0.0, [::]).
//
// The answer is the resolution of the moment: gRPC resolves the name again
// when it binds or connects, so a name whose resolution an attacker can
// change between the two could still differ (names from the hosts file,
// such as localhost, and literal addresses cannot).
#ifndef FLUXCAL_IO_NET_H_
#define FLUXCAL_IO_NET_H_

#include <string>
#include <string_view>
#include <vector>

namespace fluxcal::io {

struct LoopbackCheck {
  bool loopback = false;
  // What the address is, to follow it in a message: "is a unix socket",
  // "resolves to 127.0.0.1", "resolves to 127.0.0.1 and 10.20.0.5",
  // "does not resolve ('h.example': Name or service not known)", "has no
  // host (every interface)".
  std::string why;
  std::vector<std::string> addresses;   // numeric, as resolved
};

LoopbackCheck CheckLoopback(std::string_view address);
inline bool IsLoopbackAddress(std::string_view address) { return CheckLoopback(address).loopback; }

}  // namespace fluxcal::io

#endif  // FLUXCAL_IO_NET_H_
