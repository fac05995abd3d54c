// The client side of the isostream wire contract: connect, ask for frames, receive and decode
// them. Used by `isostream fetch`, the integration tests, the benchmarks and the viewer.
//
// Threading: a Client may be shared by threads. A Session's Send may run on one thread while
// another blocks in Read (gRPC allows one writer and one reader at a time on a stream).
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "proto/isostream.grpc.pb.h"
#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream::net {

namespace pb = ::isostream::v1;

// Triangles a client accepts in one frame: 16x a daemon's default max_triangles. A server
// that streams a frame past it is refused with RESOURCE_EXHAUSTED instead of filling memory.
inline constexpr int64_t kDefaultMaxFrameTriangles = int64_t{1} << 26;
// How long Fetch waits, once its frame is whole, for the server to end the call.
inline constexpr std::chrono::milliseconds kEndOfCallGrace{1000};

struct ClientOptions {
  std::string address = "127.0.0.1:7878";
  std::string token;       // sent as "authorization: Bearer TOKEN" when not empty
  std::string tls_ca_pem;  // PEM root certificates; empty: plaintext
  // Chunks are below 4 MiB; the explicit limit leaves room for a daemon with bigger chunks.
  int max_receive_bytes = 8 << 20;
  // Unary calls and one-shot frames fail past it, connecting included (0: no deadline: a server
  // that never completes the connection is given up after gRPC's 20 s connect timeout, one
  // that connects and never answers is waited for).
  std::chrono::milliseconds call_timeout{30000};
  // What call_timeout bounds, in the client's own words, for the message of a call past it.
  std::string call_timeout_means = "--timeout-s bounds each call, a whole frame included";
  int64_t max_frame_triangles = kDefaultMaxFrameTriangles;
};

// The PEM root certificates in `path`, for ClientOptions::tls_ca_pem. InvalidArgument for a
// file that cannot be read or holds no PEM certificate (an empty one would silently mean
// plaintext; any other gRPC reports only as a failure to connect).
absl::StatusOr<std::string> ReadTlsCa(const std::string& path);

// The message for a failed call, with a hint where the code alone says little: UNAVAILABLE
// names the address and whether TLS was used (a TLS mismatch also reads "failed to connect").
std::string ExplainCallError(const absl::Status& status, const ClientOptions& options);

// For a client program's main: gRPC's own log lines (a failed TLS handshake's "E1127 ...
// Handshake failed ...") go nowhere, since ExplainCallError says the same with what to do;
// GRPC_VERBOSITY set in the environment keeps them, for debugging.
void QuietGrpcLogs();

// gRPC status -> absl status (the codes share their numbering).
absl::Status FromGrpc(const grpc::Status& status);

// A frame as it is received: chunks decoded and appended in order.
struct Frame {
  uint64_t id = 0;
  bool coarse = false;
  OrderedMesh mesh;
  pb::FrameStats stats;  // from the last chunk
  int chunks = 0;
  int64_t bytes = 0;  // encoded bytes received
  // The first vertex of each chunk's in `mesh` (chunks carry their own copies of the vertices
  // on their seams: WeldIdenticalVertices merges those across chunks).
  std::vector<uint32_t> chunk_first_vertex;
};

// Puts chunks back together and checks that they arrive as the contract says: in chunk order,
// each frame's chunks consecutive, triangle ranges contiguous.
class FrameAssembler {
 public:
  explicit FrameAssembler(int64_t max_triangles = kDefaultMaxFrameTriangles)
      : max_triangles_(max_triangles) {}

  // Decodes `chunk` into the frame in progress (a new frame id or coarse flag starts a new
  // frame, dropping an incomplete one: that frame was superseded). DataLoss/InvalidArgument
  // for chunks that do not decode, arrive out of order, or declare more than
  // kMaxStreamChunkTriangles; ResourceExhausted, before decoding, for a chunk that takes the
  // frame past max_triangles. A refused chunk leaves the frame in progress as it was.
  absl::Status Add(const pb::FrameChunk& chunk);
  bool complete() const { return complete_; }
  const Frame& frame() const { return frame_; }
  Frame Take();

 private:
  // Add for a chunk of the frame in progress.
  absl::Status AddToFrame(const pb::FrameChunk& chunk);
  int64_t max_triangles_;
  Frame frame_;
  bool started_ = false;
  bool complete_ = false;
  uint32_t next_chunk_ = 0;
};

class Session {
 public:
  ~Session();  // cancels the stream if it was not closed
  // Sends a view; frames for earlier views may still arrive until this one's frames start.
  absl::Status Send(const pb::ViewRequest& view);
  // Blocks for the next chunk; false when the stream has ended (then call Finish).
  bool Read(pb::FrameChunk* chunk);
  // Says no more views will come (the server finishes after the frame in progress).
  absl::Status CloseSend();
  // Drains what is left and returns the stream's final status.
  absl::Status Finish();
  // Drops the stream now (as a client that disappears would).
  void Cancel();
  // Only asks gRPC to cancel: a Read blocked on another thread returns false. Safe to call while
  // that thread reads (Cancel is not: it drains the stream itself); call Finish after joining it.
  void TryCancel();

 private:
  friend class Client;
  std::unique_ptr<grpc::ClientContext> context_;
  std::unique_ptr<grpc::ClientReaderWriter<pb::ViewRequest, pb::FrameChunk>> stream_;
  bool closed_ = false, finished_ = false;
};

class Client {
 public:
  // Creates the channel; does not wait for the server (calls fail with UNAVAILABLE if it is
  // not there).
  static absl::StatusOr<std::unique_ptr<Client>> Connect(const ClientOptions& options);

  absl::StatusOr<pb::ListVolumesResponse> ListVolumes();
  absl::StatusOr<pb::VolumeInfo> GetVolumeInfo(const std::string& name, int histogram_bins = 0);
  absl::StatusOr<pb::ServerStats> GetServerStats();
  // grpc.health.v1 Check for the whole server ("") or one service by its full name: true when
  // SERVING.
  absl::StatusOr<bool> CheckHealth(const std::string& service = "");

  // One frame through Extract: returns the requested (refined) frame; `on_chunk`, if set, sees
  // every chunk as it arrives, coarse ones included.
  absl::StatusOr<Frame> Fetch(const pb::ViewRequest& view,
                              const std::function<void(const pb::FrameChunk&)>& on_chunk = {});

  absl::StatusOr<std::unique_ptr<Session>> OpenSession();

  const ClientOptions& options() const { return options_; }

 private:
  void Prepare(grpc::ClientContext* context, bool deadline) const;
  ClientOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::Isostream::Stub> stub_;
};

// How a client program's flags name the daemon (--server, --token, --tls-ca, --timeout-s).
struct ConnectionFlags {
  std::string server = "127.0.0.1:7878";
  std::string token;
  std::string tls_ca;  // a PEM file's path; empty: plaintext
  int timeout_s = 60;
  // What --timeout-s bounds, in the program's own words (ClientOptions::call_timeout_means).
  std::string timeout_means = "--timeout-s bounds each call";
};

// Sets `options`' address, token, timeout and TLS roots from `flags` (its other fields are the
// caller's) and connects. InvalidArgument for a --tls-ca file that holds no certificate or an
// address or token gRPC cannot take: the flags' fault.
absl::StatusOr<std::unique_ptr<Client>> ConnectWith(const ConnectionFlags& flags,
                                                    ClientOptions* options);

}  // namespace isostream::net
