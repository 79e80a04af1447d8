// gRPC server reflection, v1 (grpc.reflection.v1.ServerReflection) and
// v1alpha (grpc.reflection.v1alpha.ServerReflection), served from the
// generated DescriptorPool.
//
// Why not grpc++_reflection: Debian's gRPC 1.51 serves only v1alpha
// (grpcpp/ext/proto_server_reflection_plugin.h has no v1 service), and its
// handler answers whoever connects. Here every stream is authenticated
// with the service's Authorizer first: any identity, whatever its role, may
// reflect (the API description is the same for all roles and says nothing
// about stored data); a caller without a valid credential gets
// UNAUTHENTICATED, as for every other RPC but health. In open mode
// (loopback without --auth) everyone may.
#ifndef FLUXCAL_SERVER_REFLECTION_H_
#define FLUXCAL_SERVER_REFLECTION_H_

#include <memory>
#include <string>
#include <vector>

#include <grpcpp/impl/codegen/service_type.h>

#include "server/auth.h"

namespace fluxcal::server {

// The two reflection services. `services`: the fully qualified names
// list_services answers (their files are looked up in the generated pool).
// `auth` must outlive the services; nullptr means open.
std::vector<std::unique_ptr<grpc::Service>> MakeReflectionServices(const Authorizer* auth,
                                                                   std::vector<std::string> services);

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_REFLECTION_H_
