#include "server/reflection.h"

#include <set>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <grpcpp/grpcpp.h>

#include "absl/strings/str_cat.h"
#include "grpc/reflection/v1/reflection.grpc.pb.h"
#include "grpc/reflection/v1alpha/reflection.grpc.pb.h"

namespace fluxcal::server {
namespace {

namespace pb = google::protobuf;

// One implementation for both packages: the generated types differ only in
// their namespace, the wire format not at all.
template <class Base, class Req, class Resp>
class Reflection final : public Base {
 public:
  Reflection(const Authorizer* auth, std::vector<std::string> services)
      : auth_(auth), services_(std::move(services)) {}

  grpc::Status ServerReflectionInfo(grpc::ServerContext* ctx, grpc::ServerReaderWriter<Resp, Req>* stream) override {
    static const Authorizer kOpen;
    auto who = (auth_ != nullptr ? auth_ : &kOpen)->Authenticate(*ctx);
    if (!who.ok()) return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, std::string(who.status().message()));
    const pb::DescriptorPool* pool = pb::DescriptorPool::generated_pool();
    std::set<std::string> sent;   // files already sent on this stream
    Req req;
    while (stream->Read(&req)) {
      Resp resp;
      resp.set_valid_host(req.host());
      *resp.mutable_original_request() = req;
      switch (req.message_request_case()) {
        case Req::kFileByFilename:
          AddFile(pool->FindFileByName(req.file_by_filename()), "file_by_filename", req.file_by_filename(), &sent,
                  &resp);
          break;
        case Req::kFileContainingSymbol:
          AddFile(pool->FindFileContainingSymbol(req.file_containing_symbol()), "file_containing_symbol",
                  req.file_containing_symbol(), &sent, &resp);
          break;
        case Req::kFileContainingExtension: {
          const auto& e = req.file_containing_extension();
          const pb::Descriptor* type = pool->FindMessageTypeByName(e.containing_type());
          const pb::FieldDescriptor* ext =
              type != nullptr ? pool->FindExtensionByNumber(type, e.extension_number()) : nullptr;
          AddFile(ext != nullptr ? ext->file() : nullptr, "file_containing_extension",
                  absl::StrCat(e.containing_type(), " #", e.extension_number()), &sent, &resp);
          break;
        }
        case Req::kAllExtensionNumbersOfType: {
          const pb::Descriptor* type = pool->FindMessageTypeByName(req.all_extension_numbers_of_type());
          if (type == nullptr) {
            Error(grpc::StatusCode::NOT_FOUND,
                  absl::StrCat("all_extension_numbers_of_type: unknown type '", req.all_extension_numbers_of_type(), "'"),
                  &resp);
            break;
          }
          std::vector<const pb::FieldDescriptor*> exts;
          pool->FindAllExtensions(type, &exts);
          auto* r = resp.mutable_all_extension_numbers_response();
          r->set_base_type_name(type->full_name());
          for (const auto* f : exts) r->add_extension_number(f->number());
          break;
        }
        case Req::kListServices:
          for (const auto& name : services_) resp.mutable_list_services_response()->add_service()->set_name(name);
          break;
        default:
          Error(grpc::StatusCode::UNIMPLEMENTED, "message_request: not set or not supported", &resp);
          break;
      }
      if (!stream->Write(resp)) break;
    }
    return grpc::Status::OK;
  }

 private:
  static void Error(grpc::StatusCode code, const std::string& message, Resp* resp) {
    resp->mutable_error_response()->set_error_code(static_cast<int>(code));
    resp->mutable_error_response()->set_error_message(message);
  }

  // The file and, depth first, every dependency not yet sent: a client
  // needs them all to build the descriptor, and sends each only once.
  static void AddFile(const pb::FileDescriptor* file, const char* field, const std::string& what,
                      std::set<std::string>* sent, Resp* resp) {
    if (file == nullptr) {
      Error(grpc::StatusCode::NOT_FOUND, absl::StrCat(field, ": '", what, "' not found"), resp);
      return;
    }
    std::vector<const pb::FileDescriptor*> todo = {file};
    auto* out = resp->mutable_file_descriptor_response();
    while (!todo.empty()) {
      const pb::FileDescriptor* f = todo.back();
      todo.pop_back();
      // The requested file itself always goes out, its dependencies once.
      if (f != file && !sent->insert(f->name()).second) continue;
      if (f == file) sent->insert(f->name());
      pb::FileDescriptorProto proto;
      f->CopyTo(&proto);
      out->add_file_descriptor_proto(proto.SerializeAsString());
      for (int k = 0; k < f->dependency_count(); ++k) todo.push_back(f->dependency(k));
    }
  }

  const Authorizer* auth_;
  std::vector<std::string> services_;
};

}  // namespace

std::vector<std::unique_ptr<grpc::Service>> MakeReflectionServices(const Authorizer* auth,
                                                                   std::vector<std::string> services) {
  namespace r1 = grpc::reflection::v1;
  namespace ra = grpc::reflection::v1alpha;
  services.push_back(r1::ServerReflection::service_full_name());
  services.push_back(ra::ServerReflection::service_full_name());
  std::vector<std::unique_ptr<grpc::Service>> out;
  out.push_back(std::make_unique<Reflection<r1::ServerReflection::Service, r1::ServerReflectionRequest,
                                            r1::ServerReflectionResponse>>(auth, services));
  out.push_back(std::make_unique<Reflection<ra::ServerReflection::Service, ra::ServerReflectionRequest,
                                            ra::ServerReflectionResponse>>(auth, services));
  return out;
}

}  // namespace fluxcal::server
