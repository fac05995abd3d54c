// A gRPC server on 127.0.0.1 that speaks the isostream contract badly, for the clients' tests:
// a volume info with the wrong number of dims or none at all, a session that never sends a chunk,
// a frame that never ends, or a whole frame and then an error. Only what a client meets is
// implemented (GetVolumeInfo and Session).
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "proto/isostream.grpc.pb.h"
#include "shared/frame_codec.h"
#include "shared/ordered_mesh.h"

namespace isostream::testing {

enum class Misbehaviour {
  kTwoDims,          // GetVolumeInfo describes the volume with 2 dims
  kStall,            // Session reads the view and then sends nothing
  kEndlessFrame,     // Session answers the view with chunks of one frame that never ends
  kSilentInfo,       // GetVolumeInfo never answers
  kFrameThenGone,    // Session answers the view with a whole frame, then ends UNAVAILABLE
  kFrameThenSilent,  // Session and Extract answer with a whole frame, then never end the call
  kOtherFrames,      // Session answers the view with chunks of another frame, paced, without end
  kWrongFrame,       // Extract answers with a whole frame of another id, then ends OK
};

class MisbehavingServer final : public ::isostream::v1::Isostream::Service {
 public:
  // Bounds the endless frame, so a client that never gives up cannot keep the test running.
  static constexpr int kMaxChunks = 20000;
  static constexpr int kTrianglesPerChunk = 100;

  explicit MisbehavingServer(Misbehaviour how) : how_(how) {
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(this);
    server_ = builder.BuildAndStart();
  }
  ~MisbehavingServer() override {
    stop_ = true;
    if (server_) server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
  }

  bool ok() const { return server_ != nullptr && port_ > 0; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  int chunks_sent() const { return chunks_sent_.load(); }

  grpc::Status GetVolumeInfo(grpc::ServerContext* context,
                             const ::isostream::v1::GetVolumeInfoRequest* r,
                             ::isostream::v1::VolumeInfo* info) override {
    if (how_ == Misbehaviour::kSilentInfo) {
      WaitForTheClientToLeave(context);
      return grpc::Status(grpc::StatusCode::CANCELLED, "silent");
    }
    info->set_name(r->name());
    for (int a = 0; a < (how_ == Misbehaviour::kTwoDims ? 2 : 3); ++a) info->add_dims(33);
    info->mutable_spacing()->set_x(1);
    info->mutable_spacing()->set_y(1);
    info->mutable_spacing()->set_z(1);
    info->set_min_value(0);
    info->set_max_value(1);
    return grpc::Status::OK;
  }

  grpc::Status Session(grpc::ServerContext* context,
                       grpc::ServerReaderWriter<::isostream::v1::FrameChunk,
                                                ::isostream::v1::ViewRequest>* stream) override {
    ::isostream::v1::ViewRequest view;
    if (!stream->Read(&view)) return grpc::Status::OK;
    if (how_ == Misbehaviour::kFrameThenGone || how_ == Misbehaviour::kFrameThenSilent) {
      ::isostream::v1::FrameChunk chunk;
      if (!WholeFrame(view.request_id(), &chunk))
        return grpc::Status(grpc::StatusCode::INTERNAL, "cannot encode the test chunk");
      stream->Write(chunk);
      if (how_ == Misbehaviour::kFrameThenGone)
        return grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down");
      WaitForTheClientToLeave(context);
      return grpc::Status(grpc::StatusCode::CANCELLED, "silent");
    }
    if (how_ == Misbehaviour::kOtherFrames) {
      ::isostream::v1::FrameChunk chunk;
      if (!WholeFrame(view.request_id() + 1000, &chunk))
        return grpc::Status(grpc::StatusCode::INTERNAL, "cannot encode the test chunk");
      for (int i = 0; i < kMaxChunks && !context->IsCancelled() && !stop_; ++i) {
        if (!stream->Write(chunk)) break;
        ++chunks_sent_;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      return grpc::Status::OK;
    }
    if (how_ == Misbehaviour::kEndlessFrame) {
      std::string data;
      const OrderedMesh strip = Strip(kTrianglesPerChunk);
      if (!EncodeChunkRaw(strip, 0, strip.triangle_count(), &data).ok())
        return grpc::Status(grpc::StatusCode::INTERNAL, "cannot encode the test chunk");
      ::isostream::v1::FrameChunk chunk;
      chunk.set_frame_id(view.request_id());
      chunk.set_triangle_count(kTrianglesPerChunk);
      chunk.set_data(data);
      for (int i = 0; i < kMaxChunks && !context->IsCancelled() && !stop_; ++i) {
        chunk.set_chunk_index(uint32_t(i));
        chunk.set_first_triangle(uint64_t(i) * kTrianglesPerChunk);
        if (!stream->Write(chunk)) break;
        ++chunks_sent_;
      }
      return grpc::Status::OK;
    }
    WaitForTheClientToLeave(context);
    return grpc::Status(grpc::StatusCode::CANCELLED, "stalled");
  }

  grpc::Status Extract(grpc::ServerContext* context, const ::isostream::v1::ViewRequest* view,
                       grpc::ServerWriter<::isostream::v1::FrameChunk>* writer) override {
    if (how_ != Misbehaviour::kFrameThenSilent && how_ != Misbehaviour::kWrongFrame)
      return grpc::Status(grpc::StatusCode::UNIMPLEMENTED, "not in this test");
    ::isostream::v1::FrameChunk chunk;
    const bool wrong = how_ == Misbehaviour::kWrongFrame;
    if (!WholeFrame(view->request_id() + (wrong ? 1 : 0), &chunk))
      return grpc::Status(grpc::StatusCode::INTERNAL, "cannot encode the test chunk");
    writer->Write(chunk);
    if (wrong) return grpc::Status::OK;
    WaitForTheClientToLeave(context);
    return grpc::Status(grpc::StatusCode::CANCELLED, "silent");
  }

 private:
  // A whole frame of one chunk, answering `request_id`.
  static bool WholeFrame(uint64_t request_id, ::isostream::v1::FrameChunk* chunk) {
    const OrderedMesh strip = Strip(kTrianglesPerChunk);
    if (!EncodeChunkRaw(strip, 0, strip.triangle_count(), chunk->mutable_data()).ok()) return false;
    chunk->set_frame_id(request_id);
    chunk->set_last(true);
    chunk->set_chunk_count(1);
    chunk->set_triangle_count(kTrianglesPerChunk);
    chunk->mutable_stats()->set_triangles(kTrianglesPerChunk);
    return true;
  }

  // Silence until the client leaves (or the test ends, or a minute passes).
  void WaitForTheClientToLeave(grpc::ServerContext* context) const {
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!context->IsCancelled() && !stop_ && std::chrono::steady_clock::now() < give_up)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }

  // A strip of `n` triangles inside the unit cube.
  static OrderedMesh Strip(int n) {
    OrderedMesh m;
    for (int i = 0; i < n + 2; ++i) {
      const float x = float(i) / float(n + 2);
      m.positions.insert(m.positions.end(), {x, float(i % 2), 0.5f});
      m.normals.insert(m.normals.end(), {0.0f, 0.0f, 1.0f});
    }
    for (int i = 0; i < n; ++i) {
      m.triangles.insert(m.triangles.end(), {uint32_t(i), uint32_t(i + 1), uint32_t(i + 2)});
      m.surface.push_back(0);
    }
    return m;
  }

  const Misbehaviour how_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
  std::atomic<bool> stop_{false};
  std::atomic<int> chunks_sent_{0};
};

}  // namespace isostream::testing
