#include "client/net/session_client.h"

#include <grpc/support/log.h>

#include <condition_variable>
#include <cstdlib>
#include <mutex>
#include <thread>

#include "proto/health.grpc.pb.h"
#include "shared/file_io.h"
#include "shared/frame_codec.h"
#include "shared/number_list.h"

namespace isostream::net {

absl::Status FromGrpc(const grpc::Status& s) {
  if (s.ok()) return absl::OkStatus();
  return absl::Status(absl::StatusCode(int(s.error_code())), s.error_message());
}

absl::StatusOr<std::string> ReadTlsCa(const std::string& path) {
  auto pem = ReadFileBytes(path);  // refuses directories and other non-regular files
  if (!pem.ok())
    return absl::InvalidArgumentError("cannot read --tls-ca '" + path +
                                      "': " + std::string(pem.status().message()));
  // gRPC takes anything else as an empty list of roots and fails the connection attempt.
  if (pem->find("-----BEGIN CERTIFICATE-----") == std::string::npos)
    return absl::InvalidArgumentError("--tls-ca '" + path + "' holds no certificates (PEM)");
  return std::move(*pem);
}

void QuietGrpcLogs() {
  if (std::getenv("GRPC_VERBOSITY") == nullptr) gpr_set_log_function([](gpr_log_func_args*) {});
}

std::string ExplainCallError(const absl::Status& s, const ClientOptions& options) {
  const std::string m(s.message());
  switch (s.code()) {
    case absl::StatusCode::kUnavailable:
      // Refused: nothing listens there, so TLS is not the question.
      if (m.find("Connection refused") != std::string::npos)
        return "cannot reach isostreamd at " + options.address + " (" + m + ")";
      // A connection that was made and broke (the daemon stopped or was killed mid-frame)
      // reads as one of these, without gRPC's "failed to connect"; anything else (a name
      // that does not resolve, a TLS mismatch) is a daemon never reached.
      if (m.find("failed to connect") == std::string::npos) {
        for (const char* broke : {"Socket closed", "Connection reset", "Broken pipe", "GOAWAY",
                                  "shutting down", "stream is broken"})
          if (m.find(broke) != std::string::npos)
            return "lost the connection to isostreamd at " + options.address + " (" + m + ")";
      }
      return "cannot reach isostreamd at " + options.address + " (" + m + ")" +
             (options.tls_ca_pem.empty()
                  ? "; connected without TLS: if the daemon serves TLS, pass --tls-ca"
                  : "; connected with TLS: check that the daemon serves TLS with a certificate "
                    "--tls-ca trusts");
    case absl::StatusCode::kUnauthenticated:
      return "the server refused the token (" + m + "); " +
             (options.token.empty() ? "pass --token" : "check the value given to --token");
    case absl::StatusCode::kNotFound:
      return m;
    case absl::StatusCode::kDeadlineExceeded:
      // gRPC's own message: this client's deadline. The daemon's (a frame past its deadline,
      // an idle session) say what they are.
      if (m == "Deadline Exceeded" && options.call_timeout.count() > 0)
        return "the call did not complete within " +
               ShortestText(double(options.call_timeout.count()) / 1000) + " s (" +
               options.call_timeout_means + ")";
      return "DEADLINE_EXCEEDED: " + m;
    default:
      return std::string(absl::StatusCodeToString(s.code())) + ": " + m;
  }
}

absl::Status FrameAssembler::Add(const pb::FrameChunk& chunk) {
  if (started_ && !complete_ && chunk.frame_id() == frame_.id && chunk.coarse() == frame_.coarse)
    return AddToFrame(chunk);
  if (chunk.chunk_index() != 0)
    return absl::DataLossError("frame " + std::to_string(chunk.frame_id()) + " starts at chunk " +
                               std::to_string(chunk.chunk_index()));
  // A new frame, kept only if its first chunk is: a refused one leaves the frame before it
  // (a complete one, say) as it was.
  Frame before = std::move(frame_);
  const bool was_started = started_, was_complete = complete_;
  const uint32_t was_next = next_chunk_;
  frame_ = Frame();
  frame_.id = chunk.frame_id();
  frame_.coarse = chunk.coarse();
  started_ = true;
  complete_ = false;
  next_chunk_ = 0;
  const absl::Status added = AddToFrame(chunk);
  if (!added.ok()) {
    frame_ = std::move(before);
    started_ = was_started, complete_ = was_complete, next_chunk_ = was_next;
  }
  return added;
}

absl::Status FrameAssembler::AddToFrame(const pb::FrameChunk& chunk) {
  if (chunk.chunk_index() != next_chunk_)
    return absl::DataLossError("chunk " + std::to_string(chunk.chunk_index()) + " arrived, " +
                               std::to_string(next_chunk_) + " expected");
  if (chunk.first_triangle() != frame_.mesh.triangle_count())
    return absl::DataLossError("chunk triangle ranges are not contiguous");
  // Counted from the chunk's own header, before anything is decoded (its triangle_count field
  // is checked against the decoded data below).
  // A chunk the codec refuses is the server's fault, not the caller's argument: DATA_LOSS.
  auto malformed = [&](const absl::Status& s) {
    return s.code() == absl::StatusCode::kInvalidArgument
               ? absl::DataLossError("chunk " + std::to_string(chunk.chunk_index()) +
                                     " from the server is malformed: " + std::string(s.message()))
               : s;
  };
  const absl::StatusOr<ChunkHeader> read_header =
      ReadChunkHeader(chunk.data().data(), chunk.data().size());
  if (!read_header.ok()) return malformed(read_header.status());
  const ChunkHeader header = *read_header;
  // A small chunk can declare (and expand to) far more than a stream's chunks hold.
  if (header.triangle_count > kMaxStreamChunkTriangles)
    return absl::DataLossError("chunk " + std::to_string(chunk.chunk_index()) + " declares " +
                               std::to_string(header.triangle_count) +
                               " triangles; a stream's chunks hold at most " +
                               std::to_string(kMaxStreamChunkTriangles));
  if (int64_t(frame_.mesh.triangle_count()) + int64_t(header.triangle_count) > max_triangles_ ||
      int64_t(frame_.mesh.vertex_count()) + int64_t(header.vertex_count) > 3 * max_triangles_)
    return absl::ResourceExhaustedError("frame " + std::to_string(frame_.id) + " grows past " +
                                        std::to_string(max_triangles_) +
                                        " triangles, this client's limit per frame");
  const size_t before = frame_.mesh.triangle_count(), vertices_before = frame_.mesh.vertex_count();
  // The decoder appends nothing when it fails; a check after it takes the chunk back out, so a
  // refused chunk leaves the frame as it was.
  const absl::Status decoded =
      DecodeAnyChunk(chunk.data().data(), chunk.data().size(), &frame_.mesh);
  if (!decoded.ok()) return malformed(decoded);
  auto refuse = [&](const std::string& why) {
    frame_.mesh.positions.resize(3 * vertices_before);
    frame_.mesh.normals.resize(3 * vertices_before);
    frame_.mesh.triangles.resize(3 * before);
    frame_.mesh.surface.resize(before);
    return absl::DataLossError(why);
  };
  if (frame_.mesh.triangle_count() - before != chunk.triangle_count())
    return refuse("chunk triangle count does not match its data");
  // Only a frame's last chunk may be empty (an empty frame): empty chunks without end would
  // be a frame that never completes nor grows.
  if (chunk.triangle_count() == 0 && !chunk.last())
    return refuse("chunk " + std::to_string(chunk.chunk_index()) +
                  " is empty and not its frame's last");
  if (chunk.last()) {
    // The last chunk says how many chunks and triangles the frame has: a stream that ends it
    // early must not pass for the whole frame.
    if (chunk.chunk_count() != next_chunk_ + 1)
      return refuse("frame " + std::to_string(frame_.id) + " ended after " +
                    std::to_string(next_chunk_ + 1) + " chunks, its last chunk says " +
                    std::to_string(chunk.chunk_count()));
    if (chunk.has_stats() && chunk.stats().triangles() != int64_t(frame_.mesh.triangle_count()))
      return refuse("frame " + std::to_string(frame_.id) + " has " +
                    std::to_string(frame_.mesh.triangle_count()) + " triangles, its stats say " +
                    std::to_string(chunk.stats().triangles()));
    frame_.stats = chunk.stats();
    complete_ = true;
  }
  ++next_chunk_;
  ++frame_.chunks;
  frame_.bytes += int64_t(chunk.data().size());
  frame_.chunk_first_vertex.push_back(uint32_t(vertices_before));
  return absl::OkStatus();
}

Frame FrameAssembler::Take() {
  Frame f = std::move(frame_);
  frame_ = Frame();
  started_ = false;
  complete_ = false;
  return f;
}

Session::~Session() {
  if (!finished_) Cancel();
}

absl::Status Session::Send(const pb::ViewRequest& view) {
  if (closed_) return absl::FailedPreconditionError("session closed for sending");
  if (!stream_->Write(view)) return absl::UnavailableError("the session stream is broken");
  return absl::OkStatus();
}

bool Session::Read(pb::FrameChunk* chunk) { return stream_->Read(chunk); }

absl::Status Session::CloseSend() {
  if (closed_) return absl::OkStatus();
  closed_ = true;
  if (!stream_->WritesDone()) return absl::UnavailableError("the session stream is broken");
  return absl::OkStatus();
}

absl::Status Session::Finish() {
  if (finished_) return absl::FailedPreconditionError("already finished");
  pb::FrameChunk ignored;
  while (stream_->Read(&ignored)) {
  }
  finished_ = true;
  return FromGrpc(stream_->Finish());
}

void Session::TryCancel() { context_->TryCancel(); }

void Session::Cancel() {
  context_->TryCancel();
  if (!finished_) {
    pb::FrameChunk ignored;
    while (stream_->Read(&ignored)) {
    }
    finished_ = true;
    stream_->Finish();
  }
}

absl::StatusOr<std::unique_ptr<Client>> Client::Connect(const ClientOptions& options) {
  // gRPC aborts the process on metadata it cannot send: refuse such a token here.
  for (unsigned char ch : options.token)
    if (ch < 0x20 || ch > 0x7e)
      return absl::InvalidArgumentError("the token must be printable ASCII characters");
  if (options.address.empty()) return absl::InvalidArgumentError("no server address given");
  // :104903 had reached :39367, and :-1 :65535; a port that is no number (127.0.0.1:abc) or
  // none at all had gRPC try port 0 or 443. Unix socket targets have no port.
  const bool unix_socket =
      options.address.rfind("unix:", 0) == 0 || options.address.rfind("unix-abstract:", 0) == 0;
  ISOSTREAM_RETURN_IF_ERROR(CheckPort(options.address, /*required=*/!unix_socket));
  auto c = std::unique_ptr<Client>(new Client());
  c->options_ = options;
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options.max_receive_bytes);
  std::shared_ptr<grpc::ChannelCredentials> creds;
  if (options.tls_ca_pem.empty()) {
    creds = grpc::InsecureChannelCredentials();
  } else {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = options.tls_ca_pem;
    creds = grpc::SslCredentials(ssl);
  }
  c->channel_ = grpc::CreateCustomChannel(options.address, creds, args);
  if (!c->channel_)
    return absl::InvalidArgumentError("cannot create a channel to " + options.address);
  c->stub_ = pb::Isostream::NewStub(c->channel_);
  return c;
}

void Client::Prepare(grpc::ClientContext* context, bool deadline) const {
  if (!options_.token.empty()) context->AddMetadata("authorization", "Bearer " + options_.token);
  if (deadline && options_.call_timeout.count() > 0)
    context->set_deadline(std::chrono::system_clock::now() + options_.call_timeout);
}

absl::StatusOr<pb::ListVolumesResponse> Client::ListVolumes() {
  grpc::ClientContext context;
  Prepare(&context, true);
  pb::ListVolumesResponse response;
  ISOSTREAM_RETURN_IF_ERROR(
      FromGrpc(stub_->ListVolumes(&context, pb::ListVolumesRequest(), &response)));
  return response;
}

absl::StatusOr<pb::VolumeInfo> Client::GetVolumeInfo(const std::string& name, int bins) {
  grpc::ClientContext context;
  Prepare(&context, true);
  pb::GetVolumeInfoRequest request;
  request.set_name(name);
  request.set_histogram_bins(bins);
  pb::VolumeInfo response;
  ISOSTREAM_RETURN_IF_ERROR(FromGrpc(stub_->GetVolumeInfo(&context, request, &response)));
  return response;
}

absl::StatusOr<pb::ServerStats> Client::GetServerStats() {
  grpc::ClientContext context;
  Prepare(&context, true);
  pb::ServerStats response;
  ISOSTREAM_RETURN_IF_ERROR(
      FromGrpc(stub_->GetServerStats(&context, pb::GetServerStatsRequest(), &response)));
  return response;
}

absl::StatusOr<bool> Client::CheckHealth(const std::string& service) {
  auto stub = grpc::health::v1::Health::NewStub(channel_);
  grpc::ClientContext context;
  if (options_.call_timeout.count() > 0)
    context.set_deadline(std::chrono::system_clock::now() + options_.call_timeout);
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse response;
  ISOSTREAM_RETURN_IF_ERROR(FromGrpc(stub->Check(&context, request, &response)));
  return response.status() == grpc::health::v1::HealthCheckResponse::SERVING;
}

absl::StatusOr<Frame> Client::Fetch(const pb::ViewRequest& view,
                                    const std::function<void(const pb::FrameChunk&)>& on_chunk) {
  grpc::ClientContext context;
  Prepare(&context, true);
  auto reader = stub_->Extract(&context, view);
  FrameAssembler assembler(options_.max_frame_triangles);
  Frame result;
  bool have = false;
  pb::FrameChunk chunk;
  while (reader->Read(&chunk)) {
    if (on_chunk) on_chunk(chunk);
    const absl::Status added = assembler.Add(chunk);
    if (!added.ok()) {
      // Nothing more from this stream can be used: stop it instead of draining it (a server
      // streaming without end would otherwise hold the call until its deadline).
      context.TryCancel();
      while (reader->Read(&chunk)) {
      }
      (void)reader->Finish();  // CANCELLED, by us
      return added;
    }
    if (assembler.complete() && !assembler.frame().coarse) {
      result = assembler.Take();
      have = true;
      break;
    }
  }
  if (have) {
    // The frame is whole and checked. The server ends the call right after it, and waiting for
    // that lets it free the call's session slot before this returns (cancelling at once, a
    // caller's next call could find its own last one still holding the slot); a server that
    // does not end it within a grace must not turn the frame into a timeout (it did).
    std::mutex mu;
    std::condition_variable cv;
    bool ended_call = false;
    std::thread grace([&] {
      std::unique_lock<std::mutex> lock(mu);
      if (!cv.wait_for(lock, kEndOfCallGrace, [&] { return ended_call; })) context.TryCancel();
    });
    while (reader->Read(&chunk)) {
    }
    const absl::Status ended = FromGrpc(reader->Finish());
    {
      std::lock_guard<std::mutex> lock(mu);
      ended_call = true;
    }
    cv.notify_all();
    grace.join();
    // Ended by this side (the grace, or the call's own deadline running out during it): the
    // frame stands.
    if (!ended.ok() && ended.code() != absl::StatusCode::kCancelled &&
        ended.code() != absl::StatusCode::kDeadlineExceeded)
      return ended;
  } else {
    ISOSTREAM_RETURN_IF_ERROR(FromGrpc(reader->Finish()));
  }
  if (!have) return absl::DataLossError("the stream ended without a complete frame");
  if (result.id != view.request_id())
    return absl::DataLossError("the server answered request " + std::to_string(view.request_id()) +
                               " with frame " + std::to_string(result.id));
  return result;
}

absl::StatusOr<std::unique_ptr<Session>> Client::OpenSession() {
  auto s = std::unique_ptr<Session>(new Session());
  s->context_ = std::make_unique<grpc::ClientContext>();
  Prepare(s->context_.get(), false);
  s->stream_ = stub_->Session(s->context_.get());
  if (!s->stream_) return absl::UnavailableError("cannot open a session");
  return s;
}

absl::StatusOr<std::unique_ptr<Client>> ConnectWith(const ConnectionFlags& flags,
                                                    ClientOptions* options) {
  options->address = flags.server;
  options->token = flags.token;
  options->call_timeout = std::chrono::seconds(flags.timeout_s);
  options->call_timeout_means = flags.timeout_means;
  if (!flags.tls_ca.empty()) {
    auto pem = ReadTlsCa(flags.tls_ca);
    if (!pem.ok()) return pem.status();
    options->tls_ca_pem = std::move(*pem);
  }
  return Client::Connect(*options);
}

}  // namespace isostream::net
