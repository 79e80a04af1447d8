// io::CheckLoopback: an address is loopback by what it resolves to, never by
// its spelling.
#include "io/net.h"

#include "gtest/gtest.h"

namespace fluxcal::io {
namespace {

TEST(Loopback, LiteralAddressesAndLocalhost) {
  for (const char* a : {"127.0.0.1:50051", "127.3.2.1:1", "[::1]:1", "::1", "localhost:1", "localhost",
                        "ipv4:127.0.0.1:1,127.0.0.2:1", "ipv6:[::1]:1", "dns:///localhost:50051",
                        "dns://10.0.0.53/127.0.0.1:1", "[::ffff:127.0.0.1]:1", "unix:/run/fluxcal.sock",
                        "unix-abstract:fluxcal"}) {
    const LoopbackCheck c = CheckLoopback(a);
    EXPECT_TRUE(c.loopback) << a << ": expected loopback, got not (" << c.why << ")";
  }
}

TEST(Loopback, WildcardsOtherHostsAndMixedListsAreNot) {
  for (const char* a : {"0.0.0.0:50051", "[::]:50051", ":50051", "10.0.0.5:50051", "192.168.1.7",
                        "ipv4:127.0.0.1:1,10.0.0.5:1", "dns:///10.0.0.5:1", "[2001:db8::1]:1"}) {
    const LoopbackCheck c = CheckLoopback(a);
    EXPECT_FALSE(c.loopback) << a << ": expected not loopback, got loopback (" << c.why << ")";
  }
  const LoopbackCheck mixed = CheckLoopback("ipv4:127.0.0.1:1,10.0.0.5:1");
  EXPECT_EQ(mixed.why, "resolves to 127.0.0.1 and 10.0.0.5");
}

// The reported case: a name that starts like a loopback address but is a
// DNS name. It is judged by its resolution: not resolving (as here, .example
// is reserved, RFC 2606) or resolving elsewhere is not loopback.
TEST(Loopback, ANameIsJudgedByItsResolutionNotItsSpelling) {
  for (const char* a : {"127.plant.example:50051", "127.0.0.1.invalid:1", "localhost.invalid:1"}) {
    const LoopbackCheck c = CheckLoopback(a);
    EXPECT_FALSE(c.loopback) << a << " (" << c.why << ")";
    if (c.addresses.empty()) {
      EXPECT_NE(c.why.find("does not resolve"), std::string::npos) << c.why;
    }
  }
}

}  // namespace
}  // namespace fluxcal::io
