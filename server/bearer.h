// The client side of the bearer-token check (auth.h): a channel that sends
// "authorization: Bearer TOKEN" with every call, as `fluxcal --token-file`
// does. One home for the CLI, the tests and the benchmarks.
#ifndef FLUXCAL_SERVER_BEARER_H_
#define FLUXCAL_SERVER_BEARER_H_

#include <memory>
#include <optional>
#include <string>

#include <grpcpp/grpcpp.h>

namespace fluxcal::server {

// A channel to target with creds and args; every call carries the token,
// when there is one (nullopt: none; an empty token is sent as given).
std::shared_ptr<grpc::Channel> BearerChannel(const std::string& target,
                                             const std::shared_ptr<grpc::ChannelCredentials>& creds,
                                             const std::optional<std::string>& token,
                                             const grpc::ChannelArguments& args = grpc::ChannelArguments());
// The tests' and benchmarks' form: "" is no token.
inline std::optional<std::string> TokenOrNone(const std::string& token) {
  return token.empty() ? std::nullopt : std::optional<std::string>(token);
}

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_BEARER_H_
