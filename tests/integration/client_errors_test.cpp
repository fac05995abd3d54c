// How the clients' connection explains failed calls, and what Fetch makes of servers that answer
// badly (tests/integration/misbehaving_server.h).
#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "client/net/session_client.h"
#include "tests/integration/daemon_process.h"
#include "tests/integration/misbehaving_server.h"

namespace isostream::service {
namespace {

using testing::ScratchDir;

// gRPC's UNAVAILABLE covers a daemon never reached and a connection lost mid-frame (a daemon
// stopped or killed): only the first may be a TLS mismatch worth a hint; the second said
// "cannot reach" with that hint. The messages are gRPC 1.51's.
TEST(ClientErrors, SayWhetherTheConnectionWasMadeOrLost) {
  net::ClientOptions o;
  o.address = "127.0.0.1:7878";
  const std::string never = net::ExplainCallError(
      absl::UnavailableError("failed to connect to all addresses; last error: UNAVAILABLE: "
                             "ipv4:127.0.0.1:7878: Socket closed"),
      o);
  EXPECT_NE(never.find("cannot reach isostreamd at 127.0.0.1:7878"), std::string::npos) << never;
  EXPECT_NE(never.find("--tls-ca"), std::string::npos) << never;
  for (const char* lost : {"Socket closed", "Broken pipe", "recvmsg:Connection reset by peer"}) {
    const std::string m = net::ExplainCallError(absl::UnavailableError(lost), o);
    EXPECT_NE(m.find("lost the connection to isostreamd at 127.0.0.1:7878"), std::string::npos)
        << m;
    EXPECT_EQ(m.find("--tls-ca"), std::string::npos) << m;
  }
  // A name that does not resolve was never reached.
  const std::string unresolved = net::ExplainCallError(
      absl::UnavailableError("DNS resolution failed for nosuchhost:7878: C-ares status is not "
                             "ARES_SUCCESS qtype=A name=nosuchhost is_balancer=0: Domain name "
                             "not found"),
      o);
  EXPECT_NE(unresolved.find("cannot reach isostreamd"), std::string::npos) << unresolved;
  o.call_timeout = std::chrono::milliseconds(2500);
  const std::string late =
      net::ExplainCallError(absl::DeadlineExceededError("Deadline Exceeded"), o);
  EXPECT_NE(late.find("did not complete within 2.5 s"), std::string::npos) << late;
  // The daemon's own deadline is its message, not this client's timeout.
  const std::string daemon_late = net::ExplainCallError(
      absl::DeadlineExceededError("frame took longer than the daemon's deadline of 10000 ms"), o);
  EXPECT_EQ(daemon_late,
            "DEADLINE_EXCEEDED: frame took longer than the daemon's deadline of 10000 ms");
}

// Fetch against servers that answer Extract badly (tests/integration/misbehaving_server.h).
absl::StatusOr<net::Frame> FetchFrom(const testing::MisbehavingServer& server) {
  net::ClientOptions o;
  o.address = server.address();
  o.call_timeout = std::chrono::milliseconds(10000);
  auto c = net::Client::Connect(o);
  if (!c.ok()) return c.status();
  ::isostream::v1::ViewRequest view;
  view.set_volume("sphere:33");
  view.set_request_id(5);
  view.add_surfaces()->set_isovalue(0.5f);
  return (*c)->Fetch(view);
}

// A whole frame stands when the server never ends the call after it: Fetch cancels the call
// after its grace and returns the frame (the CANCELLED it caused is not the server's error).
TEST(ClientFetch, AWholeFrameStandsWhenTheServerNeverEndsTheCall) {
  testing::MisbehavingServer server(testing::Misbehaviour::kFrameThenSilent);
  ASSERT_TRUE(server.ok());
  const auto frame = FetchFrom(server);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_EQ(frame->mesh.triangle_count(), size_t(testing::MisbehavingServer::kTrianglesPerChunk));
}

// A frame answering another request is not this request's frame: DATA_LOSS.
TEST(ClientFetch, AFrameOfAnotherRequestIsDataLoss) {
  testing::MisbehavingServer server(testing::Misbehaviour::kWrongFrame);
  ASSERT_TRUE(server.ok());
  EXPECT_EQ(FetchFrom(server).status().code(), absl::StatusCode::kDataLoss);
}

// Without --timeout-s (call_timeout 0) gRPC's "Deadline Exceeded" is not this client's timeout:
// the message must not name a timeout of 0 s.
TEST(ClientErrors, ADeadlineWithoutATimeoutIsNotBlamedOnTimeoutS) {
  net::ClientOptions o;
  o.call_timeout = std::chrono::milliseconds(0);
  EXPECT_EQ(net::ExplainCallError(absl::DeadlineExceededError("Deadline Exceeded"), o),
            "DEADLINE_EXCEEDED: Deadline Exceeded");
}

}  // namespace
}  // namespace isostream::service
