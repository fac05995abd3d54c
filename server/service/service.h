// The isostream.v1.Isostream gRPC service (callback API): catalogue calls, Extract and Session
// streams, auth, limits and server counters. One reactor per stream with one write in flight
// (OnWriteDone starts the next), so a slow client slows only its own stream; extraction and
// encoding run on worker pools, never on gRPC's threads. A Session with no request and nothing
// in flight for limits.idle_timeout_s is ended with DEADLINE_EXCEEDED by a reaper thread.
#pragma once

#include <chrono>
#include <memory>

#include "proto/isostream.grpc.pb.h"
#include "server/service/config.h"

namespace isostream::service {

struct ServiceCore;

namespace internal {
namespace pbv1 = ::isostream::v1;
// The callback service with every call taking its request, and giving its response, as bytes:
// the service parses requests itself, so one that does not parse is INVALID_ARGUMENT naming
// the type expected. (gRPC takes a failed parse on a stream for the client's half-close, which
// ended a session with OK and no frame, and answers other calls UNIMPLEMENTED, no message.)
using ServiceBase = pbv1::Isostream::WithRawCallbackMethod_ListVolumes<
    pbv1::Isostream::WithRawCallbackMethod_GetVolumeInfo<
        pbv1::Isostream::WithRawCallbackMethod_Extract<
            pbv1::Isostream::WithRawCallbackMethod_Session<
                pbv1::Isostream::WithRawCallbackMethod_GetServerStats<pbv1::Isostream::Service>>>>>;
}  // namespace internal

class IsostreamService final : public internal::ServiceBase {
 public:
  explicit IsostreamService(const DaemonConfig& config);
  ~IsostreamService() override;  // waits for worker jobs; call after the server has shut down

  // Each call: its request in, its response out, as bytes (see ServiceBase).
  grpc::ServerUnaryReactor* ListVolumes(grpc::CallbackServerContext* context,
                                        const grpc::ByteBuffer* request,
                                        grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* GetVolumeInfo(grpc::CallbackServerContext* context,
                                          const grpc::ByteBuffer* request,
                                          grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* GetServerStats(grpc::CallbackServerContext* context,
                                           const grpc::ByteBuffer* request,
                                           grpc::ByteBuffer* response) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* Extract(grpc::CallbackServerContext* context,
                                                      const grpc::ByteBuffer* request) override;
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Session(
      grpc::CallbackServerContext* context) override;

  // Graceful stop, step one: new streams get UNAVAILABLE; open streams finish once the frame in
  // progress has been written (sessions then end with UNAVAILABLE, Extract with OK).
  void BeginShutdown();
  // Waits until no stream is open, at most `timeout`. True if none is open.
  bool WaitForStreams(std::chrono::milliseconds timeout);
  // Waits until no volume preparation runs, at most `timeout`; returns how many still do.
  int WaitForPreparations(std::chrono::milliseconds timeout);

  ::isostream::v1::ServerStats Stats() const;

 private:
  std::shared_ptr<ServiceCore> core_;
};

}  // namespace isostream::service
