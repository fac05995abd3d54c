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
// The callback service, with the calls that carry a request (GetVolumeInfo, Extract, Session)
// taking it as bytes: the service parses them itself, so a request that does not parse is
// INVALID_ARGUMENT. (gRPC reports a failed parse on a stream as the client's half-close, which
// ended a session with OK and no frame, and answers the others UNIMPLEMENTED with no message.)
using ServiceBase = pbv1::Isostream::WithCallbackMethod_ListVolumes<
    pbv1::Isostream::WithRawCallbackMethod_GetVolumeInfo<
        pbv1::Isostream::WithRawCallbackMethod_Extract<pbv1::Isostream::WithRawCallbackMethod_Session<
            pbv1::Isostream::WithCallbackMethod_GetServerStats<pbv1::Isostream::Service>>>>>;
}  // namespace internal

class IsostreamService final : public internal::ServiceBase {
 public:
  explicit IsostreamService(const DaemonConfig& config);
  ~IsostreamService() override;  // waits for worker jobs; call after the server has shut down

  grpc::ServerUnaryReactor* ListVolumes(grpc::CallbackServerContext* context,
                                        const ::isostream::v1::ListVolumesRequest* request,
                                        ::isostream::v1::ListVolumesResponse* response) override;
  // A GetVolumeInfoRequest in, a VolumeInfo out, as bytes (see ServiceBase).
  grpc::ServerUnaryReactor* GetVolumeInfo(grpc::CallbackServerContext* context,
                                          const grpc::ByteBuffer* request,
                                          grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* GetServerStats(grpc::CallbackServerContext* context,
                                           const ::isostream::v1::GetServerStatsRequest* request,
                                           ::isostream::v1::ServerStats* response) override;
  // A ViewRequest in, FrameChunks out, as bytes (see ServiceBase).
  grpc::ServerWriteReactor<grpc::ByteBuffer>* Extract(grpc::CallbackServerContext* context,
                                                      const grpc::ByteBuffer* request) override;
  // ViewRequests in, FrameChunks out, as bytes (see ServiceBase).
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Session(
      grpc::CallbackServerContext* context) override;

  // Graceful stop, step one: new streams get UNAVAILABLE; open streams finish once the frame in
  // progress has been written (sessions then end with UNAVAILABLE, Extract with OK).
  void BeginShutdown();
  // Waits until no stream is open, at most `timeout`. True if none is open.
  bool WaitForStreams(std::chrono::milliseconds timeout);

  ::isostream::v1::ServerStats Stats() const;

 private:
  std::shared_ptr<ServiceCore> core_;
};

}  // namespace isostream::service
