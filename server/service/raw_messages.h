// Requests and responses as bytes (service.h, ServiceBase): parsing a request with an error
// that names the message type expected, the start and the OK finish of a unary call. Private
// to server/service.
#pragma once

#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/codegen/proto_utils.h>

#include "absl/status/status.h"
#include "server/service/service_core.h"

namespace isostream::service {

// A request that does not parse gets INVALID_ARGUMENT naming the message type expected.
template <class Message>
absl::Status Parse(const grpc::ByteBuffer& bytes, Message* message) {
  grpc::ByteBuffer copy(bytes);  // shares the slices; Deserialize consumes its buffer
  message->Clear();
  if (grpc::SerializationTraits<Message>::Deserialize(&copy, message).ok()) return absl::OkStatus();
  return absl::InvalidArgumentError("the request is not an " + Message::descriptor()->full_name());
}

// The start of every unary call: the token, then the request. False once it has finished the
// call with the reason.
template <class Request>
bool AcceptUnary(const ServiceCore& core, grpc::CallbackServerContext* context,
                 grpc::ServerUnaryReactor* reactor, const grpc::ByteBuffer& bytes,
                 Request* request) {
  if (!core.Authorized(context)) {
    reactor->Finish(
        grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "missing or wrong bearer token"));
    return false;
  }
  const absl::Status parsed = Parse(bytes, request);
  if (!parsed.ok()) reactor->Finish(ToGrpc(parsed));
  return parsed.ok();
}

// Finishes a unary call OK with `response`, sent as bytes.
template <class Message>
void FinishWith(grpc::ServerUnaryReactor* reactor, const Message& response,
                grpc::ByteBuffer* bytes) {
  bool own = false;
  if (!grpc::SerializationTraits<Message>::Serialize(response, bytes, &own).ok())
    return reactor->Finish(
        grpc::Status(grpc::StatusCode::INTERNAL, "cannot serialize the response"));
  reactor->Finish(grpc::Status::OK);
}

}  // namespace isostream::service
