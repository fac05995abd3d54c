// The daemon's parts without a process: config parsing, catalogue names, quantization, volume
// histograms, retained frames, and how the client explains failed calls (the frame producer's
// are in frame_producer_test.cpp).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <mutex>
#include <thread>

#include "client/net/session_client.h"
#include "server/service/catalogue.h"
#include "server/service/config.h"
#include "server/service/frame_producer.h"
#include "server/service/volume_histogram.h"
#include "tests/integration/daemon_process.h"
#include "tests/integration/misbehaving_server.h"

namespace isostream::service {
namespace {

using testing::ScratchDir;

// A width x 2 x 2 volume of uint8 samples value(x), prepared as the daemon does.
PreparedVolume IntegerRamp(
    const ScratchDir& dir, int width, const std::string& name,
    const std::function<int(int)>& value = [](int x) { return x; }) {
  std::vector<char> bytes;
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < width; ++x) bytes.push_back(char(value(x)));
  const std::string path = dir.path() + "/" + name;
  std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  auto p = PrepareVolume("raw:" + path + ":" + std::to_string(width) + "x2x2:uint8", VolumeLimits{},
                         HierarchyCacheOptions{}, HierarchyBuildOptions{});
  EXPECT_TRUE(p.ok()) << p.status();
  return std::move(*p);
}

// Bin i covers [min + i w, min + (i + 1) w): a sample on an edge is counted above it, whatever
// the bin count (integer data meet every edge when w divides the range). Dividing before
// multiplying put 29 of 0..100 in bin 28 of 100.
TEST(VolumeHistograms, SamplesOnBinEdgesCountInTheBinAbove) {
  ScratchDir dir;
  const PreparedVolume ramp = IntegerRamp(dir, 101, "ramp.raw");
  const VolumeHistograms histograms;
  for (int bins : {100, 50, 25, 20, 10, 7, 4, 3, 2}) {
    SCOPED_TRACE(bins);
    std::vector<uint64_t> expected(size_t(bins), 0);
    for (int x = 0; x <= 100; ++x) expected[std::min(bins - 1, x * bins / 100)] += 4;
    const auto counts = histograms.Get(*ramp.volume, *ramp.hierarchy, bins, [] { return false; });
    ASSERT_TRUE(counts.has_value());
    EXPECT_EQ(*counts, expected);
  }
  // A constant volume: every sample is the maximum, in the closed last bin.
  const PreparedVolume flat = IntegerRamp(dir, 2, "flat.raw", [](int) { return 7; });
  const auto counts =
      VolumeHistograms().Get(*flat.volume, *flat.hierarchy, 4, [] { return false; });
  ASSERT_TRUE(counts.has_value());
  EXPECT_EQ(*counts, (std::vector<uint64_t>{0, 0, 0, 8}));
}

// Eight bin counts are kept; a ninth replaces the least recently used one only (all were
// dropped, so a client cycling through nine paid a whole pass every call). A kept count is
// answered without a pass, which is what a pass that would be cancelled at once shows.
TEST(VolumeHistograms, KeepsTheRecentlyUsedBinCounts) {
  ScratchDir dir;
  const PreparedVolume ramp = IntegerRamp(dir, 101, "ramp.raw");
  const VolumeHistograms histograms;
  auto get = [&](int bins, bool cancelled) {
    return histograms.Get(*ramp.volume, *ramp.hierarchy, bins, [=] { return cancelled; });
  };
  for (int bins = 2; bins <= 9; ++bins) ASSERT_TRUE(get(bins, false).has_value());
  ASSERT_TRUE(get(2, true).has_value());    // kept, and now the most recently used
  ASSERT_TRUE(get(10, false).has_value());  // replaces 3
  EXPECT_FALSE(get(3, true).has_value());
  for (int bins : {2, 4, 5, 6, 7, 8, 9, 10}) EXPECT_TRUE(get(bins, true).has_value()) << bins;
}

absl::Status LoadText(const std::string& text, DaemonConfig* c) {
  ScratchDir dir;
  const std::string path = dir.path() + "/c.json";
  std::ofstream(path) << text;
  return LoadConfigFile(path, c);
}

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

// Relative paths in a config file are the file's own: catalogue files (a .vdb's #GRID and a raw
// spec's layout kept), the cache directory, the TLS files; generators and absolute paths stay.
TEST(Config, RelativePathsAreTheFilesOwn) {
  ScratchDir dir;
  std::filesystem::create_directories(dir.path() + "/etc");
  const std::string path = dir.path() + "/etc/c.json";
  std::ofstream(path) << R"({"volumes": {"n": "data/head.nii.gz", "v": "../v.vdb#density",
                                         "r": "raw:r.raw:4x4x4:float32", "g": "sphere:9",
                                         "a": "/srv/a.nii"},
                             "cache_dir": "cache", "tls": {"cert": "c.pem", "key": "/k.pem"}})";
  DaemonConfig c;
  ASSERT_TRUE(LoadConfigFile(path, &c).ok());
  const std::string etc = dir.path() + "/etc/";
  EXPECT_EQ(c.volumes.at("n"), etc + "data/head.nii.gz");
  EXPECT_EQ(c.volumes.at("v"), etc + "../v.vdb#density");
  EXPECT_EQ(c.volumes.at("r"), "raw:" + etc + "r.raw:4x4x4:float32");
  EXPECT_EQ(c.volumes.at("g"), "sphere:9");
  EXPECT_EQ(c.volumes.at("a"), "/srv/a.nii");
  EXPECT_EQ(c.cache_dir, etc + "cache");
  EXPECT_EQ(c.tls_cert, etc + "c.pem");
  EXPECT_EQ(c.tls_key, "/k.pem");
}

TEST(Config, ReadsKnownKeysAndNamesBadOnes) {
  DaemonConfig c;
  ASSERT_TRUE(LoadText(R"({"listen": "127.0.0.1:9", "volumes": {"a": "sphere:9"},
                           "limits": {"max_sessions": 2, "idle_timeout_s": 5},
                           "frames": {"chunk_triangles": 1024, "retain_mb": 64}})",
                       &c)
                  .ok());
  EXPECT_EQ(c.listen, "127.0.0.1:9");
  EXPECT_EQ(c.volumes.at("a"), "sphere:9");
  EXPECT_EQ(c.limits.max_sessions, 2);
  EXPECT_EQ(c.limits.idle_timeout_s, 5);
  EXPECT_EQ(c.limits.max_isovalues, 16);  // untouched default
  EXPECT_EQ(DaemonConfig().limits.idle_timeout_s, 300);
  EXPECT_EQ(c.chunk_triangles, 1024);
  EXPECT_EQ(c.retain_mb, 64);
  EXPECT_EQ(DaemonConfig().retain_mb, 1024);
  EXPECT_TRUE(c.preload);  // the default
  ASSERT_TRUE(LoadText(R"({"preload": false})", &c).ok());
  EXPECT_FALSE(c.preload);

  absl::Status s = LoadText(R"({"limits": {"max_sesions": 2}})", &c);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("limits.max_sesions"), std::string::npos) << s;
  s = LoadText(R"({"threads": "two"})", &c);
  EXPECT_NE(s.message().find("threads"), std::string::npos) << s;
  EXPECT_EQ(LoadText("{not json", &c).code(), absl::StatusCode::kInvalidArgument);
  // Where the text stops being JSON, and what the file holds there, printed escaped.
  s = LoadText("{\n  \"threads\": 2,\n  \"listen\": \"127.0.0.1:1\"\n  \"token\": 1\n}", &c);
  EXPECT_NE(s.message().find("is not valid JSON: parse error at line 4, column 9"),
            std::string::npos)
      << s;
  EXPECT_EQ(s.message().find("json.exception"), std::string::npos) << s;
  // A number past double's range is no parse error to the parser, but no less the file's.
  s = LoadText(R"({"threads": 1e400})", &c);
  EXPECT_NE(s.message().find("is not valid JSON: number overflow"), std::string::npos) << s;
  EXPECT_EQ(s.message().find("json.exception"), std::string::npos) << s;
  s = LoadText(R"({"a\u001b[2Jb": 1, "a\u001b[2Jb": 2})", &c);
  EXPECT_NE(s.message().find("key 'a\\x1b[2Jb' is given twice"), std::string::npos) << s;
  EXPECT_EQ(LoadConfigFile("/nonexistent/x.json", &c).code(), absl::StatusCode::kNotFound);

  DaemonConfig bad;
  bad.chunk_triangles = 1 << 20;  // would not fit a gRPC message
  EXPECT_FALSE(ValidateConfig(bad).ok());
  bad = DaemonConfig();
  bad.tls_cert = "cert.pem";  // no key
  EXPECT_FALSE(ValidateConfig(bad).ok());
  bad = DaemonConfig();
  bad.limits.idle_timeout_s = -1;
  EXPECT_FALSE(ValidateConfig(bad).ok());
  bad.limits.idle_timeout_s = 0;  // off
  EXPECT_TRUE(ValidateConfig(bad).ok());
  bad.retain_mb = -1;
  EXPECT_NE(ValidateConfig(bad).message().find("retain_mb"), std::string::npos);
  bad.retain_mb = 0;  // off
  EXPECT_TRUE(ValidateConfig(bad).ok());
  EXPECT_TRUE(ValidateConfig(DaemonConfig()).ok());
}

// Values that would be cut, wrapped or ignored are refused, naming what is wrong.
TEST(Config, RefusesValuesItCouldOnlyMisread) {
  auto message = [](const std::string& text) {
    DaemonConfig c;
    const absl::Status s = LoadText(text, &c);
    return std::string(s.ok() ? ValidateConfig(c).message() : s.message());
  };
  EXPECT_NE(message(R"({"limits": {"max_triangles": 1e20}})").find("whole number"),
            std::string::npos);
  EXPECT_NE(message(R"({"limits": {"max_sessions": 2.5}})").find("max_sessions"),
            std::string::npos);
  EXPECT_NE(message(R"({"threads": 99999999999})").find("threads"), std::string::npos);
  EXPECT_NE(message(R"({"threads": 1, "threads": 2})").find("'threads' is given twice"),
            std::string::npos);
  EXPECT_NE(message(R"({"volumes": {"a": "sphere:9", "a": "cayley:9"}})").find("'a'"),
            std::string::npos);
  EXPECT_EQ(message(R"({"volumes": {"a": "sphere:9"}, "limits": {"max_sessions": 2}})"), "");
  EXPECT_NE(message(R"({"shutdown_grace_ms": -1})").find("shutdown_grace_ms"), std::string::npos);
  EXPECT_NE(message(R"({"log_level": "shouty"})").find("log_level"), std::string::npos);
  EXPECT_EQ(message(R"({"log_level": "warn"})"), "");
  EXPECT_NE(message("[]").find("the configuration must be a JSON object"), std::string::npos);
  EXPECT_NE(message(R"({"tls": 5})").find("'tls' must be a JSON object"), std::string::npos);
  for (const char* listen : {"127.0.0.1:70000", "127.0.0.1:65536", "127.0.0.1", "127.0.0.1:", ":80",
                             "127.0.0.1:-1", "127.0.0.1:8o"})
    EXPECT_NE(message(std::string(R"({"listen": ")") + listen + "\"}").find("listen"),
              std::string::npos)
        << listen;
  for (const char* listen : {"127.0.0.1:0", "0.0.0.0:65535", "[::1]:7878", "localhost:7878"})
    EXPECT_EQ(message(std::string(R"({"listen": ")") + listen + "\"}"), "") << listen;
  // Bounds past which the daemon could not work: every frame failed at once past ~9.2e12 ms
  // (clock overflow), and each session slot is a thread made at start.
  EXPECT_NE(message(R"({"limits": {"deadline_ms": 10000000000000}})").find("deadline_ms"),
            std::string::npos);
  EXPECT_NE(message(R"({"limits": {"max_sessions": 2000000000}})").find("max_sessions"),
            std::string::npos);
  EXPECT_NE(message(R"({"limits": {"generator_mb": 0}})").find("generator_mb"), std::string::npos);
  EXPECT_EQ(message(R"({"limits": {"generator_mb": 100}})"), "");
  EXPECT_NE(message("{\"token\": \"caf\u00e9\"}").find("printable ASCII"), std::string::npos);
  EXPECT_EQ(message(R"({"token": "a b"})"), "");
  // Spaces around a header value do not reach the check: such a token refused every call.
  EXPECT_EQ(message(R"({"token": " s3cret"})"),
            "token must not start or end with a space (no client could present it)");
  EXPECT_NE(message(R"({"token": "s3cret "})").find("must not start or end with a space"),
            std::string::npos);
  EXPECT_NE(message(R"({"token": ""})").find("'token' is empty"), std::string::npos);
  // Whole numbers written as JSON floats are whole numbers.
  DaemonConfig c;
  ASSERT_TRUE(LoadText(R"({"limits": {"deadline_ms": 1e3, "max_sessions": 3.0}})", &c).ok());
  EXPECT_EQ(c.limits.deadline_ms, 1000);
  EXPECT_EQ(c.limits.max_sessions, 3);
  // 2^63 written as a float is past int64 (the bound once let it through, to INT64_MIN).
  EXPECT_NE(message(R"({"limits": {"max_triangles": 9223372036854775807.0}})").find("whole number"),
            std::string::npos);
  // A first chunk that was written is checked whatever its value, the default's included; only
  // one left out follows a smaller chunk_triangles.
  EXPECT_NE(message(R"({"frames": {"chunk_triangles": 4096, "first_chunk_triangles": 8192}})")
                .find("first_chunk_triangles must be in 256..chunk_triangles"),
            std::string::npos);
  EXPECT_EQ(message(R"({"frames": {"chunk_triangles": 4096, "first_chunk_triangles": 4096}})"), "");
  EXPECT_EQ(message(R"({"frames": {"chunk_triangles": 4096}})"), "");
  DaemonConfig first;
  ASSERT_TRUE(LoadText(R"({"frames": {"chunk_triangles": 4096}})", &first).ok());
  EXPECT_EQ(FirstChunkTriangles(first), 4096);
  EXPECT_EQ(FirstChunkTriangles(DaemonConfig()), kDefaultFirstChunkTriangles);
  ASSERT_TRUE(LoadText(R"({"frames": {"first_chunk_triangles": 300}})", &first).ok());
  EXPECT_EQ(FirstChunkTriangles(first), 300);
  // A directory is named as one, not as invalid JSON.
  ScratchDir dir;
  const absl::Status folder = LoadConfigFile(dir.path(), &c);
  EXPECT_NE(folder.message().find("is a directory"), std::string::npos) << folder;
  // A file it cannot open is named with the reason (a service's user may lack the permission).
  const absl::Status missing = LoadConfigFile(dir.path() + "/none.json", &c);
  EXPECT_NE(missing.message().find("none.json': No such file or directory"), std::string::npos)
      << missing;
}

// Every setting written is the one used (one the parser skipped kept its default unsaid), and the
// bounds are those the messages give, both ends included.
TEST(Config, EachSettingIsReadAndBoundedAsItsMessageSays) {
  auto message = [](const std::string& text) {
    DaemonConfig c;
    const absl::Status s = LoadText(text, &c);
    return std::string(s.ok() ? ValidateConfig(c).message() : s.message());
  };
  DaemonConfig c;
  ASSERT_TRUE(LoadText(R"({"cache_max_mb": 512,
                           "frames": {"max_queued_chunks": 4, "coarse_triangles": 5000}})",
                       &c)
                  .ok());
  EXPECT_EQ(c.cache_max_mb, 512);
  EXPECT_EQ(c.max_queued_chunks, 4);
  EXPECT_EQ(c.coarse_triangles, 5000);
  // An integer setting takes its type's whole range, and nothing past either end (a negative
  // number past int, as an integer or a float, wrapped or converted to INT_MIN).
  ASSERT_TRUE(LoadText(R"({"limits": {"max_triangles": 9223372036854775807}})", &c).ok());
  EXPECT_EQ(c.limits.max_triangles, std::numeric_limits<int64_t>::max());
  for (const char* threads : {"-3000000000", "-3e9"})
    EXPECT_NE(message(std::string(R"({"threads": )") + threads + "}")
                  .find("'threads' must be a whole number in -2147483648..2147483647"),
              std::string::npos)
        << threads << ": " << message(std::string(R"({"threads": )") + threads + "}");
  EXPECT_EQ(message(R"({"limits": {"max_dim": 1025}})"), "");
  EXPECT_EQ(message(R"({"limits": {"max_dim": 1026}})"), "max_dim (--max-dim) must be in 2..1025");
  EXPECT_EQ(message(R"({"frames": {"max_queued_chunks": 2}})"), "");
  EXPECT_EQ(message(R"({"frames": {"max_queued_chunks": 1}})"),
            "max_queued_chunks must be in 2..256");
  EXPECT_EQ(message(R"({"frames": {"coarse_triangles": 100}})"), "");
  EXPECT_EQ(message(R"({"frames": {"coarse_triangles": 99}})"),
            "coarse_triangles must be at least 100");
  // DEL is a control character too: gRPC refuses it in a header value.
  EXPECT_EQ(message(R"({"token": "ab\u007fcd"})"),
            "token must be printable ASCII (no control or non-ASCII characters)");
  EXPECT_EQ(message(R"({"volumes": {"": "sphere:9"}})"),
            "catalogue names and specs must not be empty");
  // A key in a nested object is its object's: a key of the same name outside it is no repeat.
  EXPECT_EQ(message(R"({"volumes": {"threads": "sphere:9"}, "threads": 2})"), "");
  EXPECT_EQ(message(R"({"limits": {"max_dim": 65}, "volumes": {"max_dim": "sphere:9"}})"), "");
  // Of several repeated keys, the first is named.
  EXPECT_NE(message(R"({"threads": 1, "listen": "a:1", "threads": 2, "listen": "b:2"})")
                .find(": key 'threads' is given twice"),
            std::string::npos)
      << message(R"({"threads": 1, "listen": "a:1", "threads": 2, "listen": "b:2"})");
  // A nested key is named with its object's.
  EXPECT_NE(message(R"({"tls": {"cert": "c.pem", "kee": "k.pem"}})").find("unknown key 'tls.kee'"),
            std::string::npos)
      << message(R"({"tls": {"cert": "c.pem", "kee": "k.pem"}})");
}

// The example deploy/ ships names every key with a valid value.
TEST(Config, ExampleConfigLoadsAndValidates) {
  DaemonConfig c;
  const absl::Status loaded = LoadConfigFile(ISOSTREAM_EXAMPLE_CONFIG, &c);
  ASSERT_TRUE(loaded.ok()) << loaded;
  EXPECT_TRUE(ValidateConfig(c).ok());
  EXPECT_EQ(c.volumes.size(), 2u);
  EXPECT_EQ(c.retain_mb, 1024);
}

TEST(Catalogue, GeneratorNamesOnlyWithinTheLimit) {
  CatalogueOptions o;
  o.max_generator_dim = 65;
  VolumeCatalogue generators(o);
  EXPECT_TRUE(generators.Check("buckyball:65").ok());
  EXPECT_TRUE(generators.Check("noise:33:7").ok());
  // Seeds cover [0, 2^32), as the CLI's generators take them.
  EXPECT_TRUE(generators.Check("noise:33:2147483648").ok());
  EXPECT_TRUE(generators.Check("noise:33:4294967295").ok());
  EXPECT_TRUE(generators.Check("noise:33:0").ok());
  for (const char* bad : {"buckyball:66", "buckyball:1", "buckyball", "buckyball:6x", "sphere:9:1",
                          "/etc/passwd", "x.vdb", "raw:/a:2x2x2:f32",
                          "noise:9:", "noise:9:4294967296", "noise:9:99999999999", "noise:9:-1",
                          // one spelling per volume: these would be prepared again, and held
                          "sphere:065", "sphere:0065", "noise:33:0007", "noise:033:7"})
    EXPECT_EQ(generators.Check(bad).code(), absl::StatusCode::kNotFound) << bad;
  o.volumes = {{"head", "/data/head.nii.gz"}};
  VolumeCatalogue named(o);
  EXPECT_TRUE(named.Check("head").ok());
  EXPECT_EQ(named.Check("buckyball:65").code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(named.Check("/data/head.nii.gz").code(), absl::StatusCode::kNotFound);
  // An unknown name is answered with the names there are (at most ten of them).
  EXPECT_NE(named.Check("Head").message().find("the catalogue has 'head'"), std::string::npos)
      << named.Check("Head");
  for (int i = 0; i < 12; ++i) o.volumes["v" + std::to_string(10 + i)] = "sphere:9";
  const std::string many(VolumeCatalogue(o).Check("x").message());
  EXPECT_NE(many.find("'head', 'v10', "), std::string::npos) << many;
  EXPECT_NE(many.find("'v18' and 3 more"), std::string::npos) << many;
}

// What an unknown name is answered with: no name at all is said to be none; a long name is
// quoted shortened (a status past gRPC's metadata limit reached the client as
// RESOURCE_EXHAUSTED); a list of exactly ten names is the whole list.
TEST(Catalogue, UnknownNamesAreQuotedWithinBounds) {
  CatalogueOptions o;
  const absl::Status none = VolumeCatalogue(o).Check("");
  EXPECT_EQ(none.code(), absl::StatusCode::kInvalidArgument) << none;
  EXPECT_EQ(none.message(), "no volume named");
  for (int i = 0; i < 10; ++i) o.volumes["v" + std::to_string(10 + i)] = "sphere:9";
  VolumeCatalogue named(o);
  EXPECT_EQ(named.Check("").message(), "no volume named");
  const std::string list =
      "'v10', 'v11', 'v12', 'v13', 'v14', 'v15', 'v16', 'v17', 'v18', 'v19' (`isostream "
      "volumes` lists them)";
  EXPECT_EQ(named.Check("x").message(), "unknown volume 'x'; the catalogue has " + list);
  const std::string hundred(100, 'h');
  EXPECT_EQ(named.Check(hundred).message(),
            "unknown volume '" + hundred + "'; the catalogue has " + list);
  EXPECT_EQ(named.Check(hundred + "xyz").message(),
            "unknown volume '" + hundred + "...' (103 bytes); the catalogue has " + list);
}

TEST(Catalogue, KeepsABoundedNumberOfGeneratorVolumes) {
  CatalogueOptions o;
  o.max_generator_volumes = 2;
  VolumeCatalogue catalogue(o);
  auto first = catalogue.Get("sphere:9");
  ASSERT_TRUE(first.ok());
  ASSERT_TRUE(catalogue.Get("sphere:10").ok());
  ASSERT_TRUE(catalogue.Get("sphere:9").ok());   // now the most recent
  ASSERT_TRUE(catalogue.Get("sphere:11").ok());  // drops sphere:10
  EXPECT_EQ(catalogue.held_count(), 2);
  EXPECT_EQ(catalogue.prepared_count(), 3);
  auto again = catalogue.Get("sphere:9");
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->get(), first->get());  // kept, not rebuilt
  ASSERT_TRUE(catalogue.Get("sphere:10").ok());
  EXPECT_EQ(catalogue.prepared_count(), 4);  // rebuilt after being dropped
}

// noise:N:1 and noise:N are one volume (seed 1 is the default): it was prepared and held twice.
TEST(Catalogue, HoldsTheDefaultNoiseSeedUnderOneName) {
  CatalogueOptions o;
  VolumeCatalogue catalogue(o);
  auto plain = catalogue.Get("noise:9");
  auto seeded = catalogue.Get("noise:9:1");
  ASSERT_TRUE(plain.ok() && seeded.ok());
  EXPECT_EQ(plain->get(), seeded->get());
  EXPECT_EQ(catalogue.prepared_count(), 1);
  auto other = catalogue.Get("noise:9:11");  // another seed, another volume
  ASSERT_TRUE(other.ok());
  EXPECT_NE(other->get(), plain->get());
  EXPECT_EQ(catalogue.prepared_count(), 2);
}

// Generated volumes are bounded by their memory too: the count alone (8) let the clients of a
// --max-dim 1025 daemon make it hold 8 x 6.6 GB. A 33^3 volume's store is 384,000 bytes, a
// 17^3 one's 82,944, a 65^3 one's 2,239,488.
TEST(Catalogue, KeepsGeneratorVolumesWithinAByteBudget) {
  CatalogueOptions o;
  o.max_generator_bytes = 1'000'000;  // two 33^3 volumes, not three
  VolumeCatalogue catalogue(o);
  auto first = catalogue.Get("sphere:33");
  ASSERT_TRUE(first.ok());
  ASSERT_TRUE(catalogue.Get("cayley:33").ok());
  ASSERT_TRUE(catalogue.Get("sphere:33").ok());  // now the most recent
  ASSERT_TRUE(catalogue.Get("noise:33").ok());   // drops cayley:33
  EXPECT_EQ(catalogue.held_count(), 2);
  auto again = catalogue.Get("sphere:33");
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->get(), first->get());  // kept, not rebuilt
  EXPECT_EQ(catalogue.prepared_count(), 3);
  ASSERT_TRUE(catalogue.Get("sphere:17").ok());  // a small one fits beside them
  EXPECT_EQ(catalogue.held_count(), 3);
  // One past the whole budget is refused, and nothing is dropped for it.
  auto big = catalogue.Get("sphere:65");
  EXPECT_EQ(big.status().code(), absl::StatusCode::kResourceExhausted) << big.status();
  EXPECT_NE(big.status().message().find("'sphere:65' needs 3 MiB, more than the 1 MiB"),
            std::string::npos)
      << big.status();
  EXPECT_EQ(catalogue.held_count(), 3);
  EXPECT_EQ(catalogue.prepared_count(), 4);
}

// Volumes being prepared cannot be dropped: one that does not fit beside them is refused until
// they are ready (the hook slows each preparation to 400 ms).
TEST(Catalogue, RefusesAGeneratorVolumeThatOthersBeingPreparedLeaveNoRoomFor) {
  CatalogueOptions o;
  o.max_generator_bytes = 1'000'000;
  o.prepare_delay = std::chrono::milliseconds(400);
  VolumeCatalogue catalogue(o);
  std::thread a([&] { EXPECT_TRUE(catalogue.Get("sphere:33").ok()); });
  std::thread b([&] { EXPECT_TRUE(catalogue.Get("cayley:33").ok()); });
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  auto refused = catalogue.Get("noise:33");
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kResourceExhausted) << refused.status();
  EXPECT_NE(refused.status().message().find("try again"), std::string::npos) << refused.status();
  a.join();
  b.join();
  EXPECT_TRUE(catalogue.Get("noise:33").ok());  // drops the least recently used now
  EXPECT_EQ(catalogue.held_count(), 2);
}

// A generated volume that failed to prepare holds nothing: not its bytes, not its name (asked
// again, it is tried again at once; a catalogue file's failure is remembered, a generator's is
// the request's).
TEST(Catalogue, AGeneratedVolumeThatFailedHoldsNothing) {
  CatalogueOptions o;
  o.limits.max_voxels = 1000;  // the name passes the check; preparing it does not
  VolumeCatalogue catalogue(o);
  auto failed = catalogue.Get("sphere:33");
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.status().code(), absl::StatusCode::kResourceExhausted) << failed.status();
  EXPECT_EQ(catalogue.held_count(), 0);
  EXPECT_FALSE(catalogue.Get("sphere:33").ok());
  EXPECT_EQ(catalogue.held_count(), 0);
}

// A preparation is charged its samples, 6 bytes a stored point (the floats and half as much
// again), beside the stores: two 33^3 volumes (384,000 bytes of store and 215,622 of samples
// each) do not prepare together within 1,100,000 bytes, and the second waits for the first.
TEST(Catalogue, PreparationsWhoseSamplesDoNotFitBesideTheStoresWait) {
  CatalogueOptions o;
  o.max_generator_bytes = 1'100'000;
  o.prepare_delay = std::chrono::milliseconds(500);
  VolumeCatalogue catalogue(o);
  const auto start = std::chrono::steady_clock::now();
  std::thread a([&] { EXPECT_TRUE(catalogue.Get("sphere:33").ok()); });
  std::thread b([&] { EXPECT_TRUE(catalogue.Get("cayley:33").ok()); });
  a.join();
  b.join();
  EXPECT_GE(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(1000));
  EXPECT_EQ(catalogue.held_count(), 2);
}

// A preparation that has started runs to its end though its only client gave up: the next
// request for the volume waits for it rather than starting a second build.
TEST(Catalogue, AStartedPreparationOutlivesTheClientThatGaveUp) {
  CatalogueOptions o;
  o.prepare_delay = std::chrono::milliseconds(800);
  VolumeCatalogue catalogue(o);
  // The client gives up once the preparation has left the queue (started), however long a busy
  // machine took to start it: the cancel check runs under the catalogue's lock, so another
  // thread watches.
  std::atomic<bool> started{false};
  std::thread watcher([&] {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < until &&
           !(catalogue.held_count() == 1 && catalogue.queued_preparations() == 0))
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    started = true;
  });
  auto given_up = catalogue.Get("sphere:17", [&] { return started.load(); });
  watcher.join();
  EXPECT_EQ(given_up.status().code(), absl::StatusCode::kCancelled) << given_up.status();
  EXPECT_EQ(catalogue.held_count(), 1);  // still being prepared
  ASSERT_TRUE(catalogue.Get("sphere:17").ok());
  EXPECT_EQ(catalogue.prepared_count(), 1);
}

// Views given up while their volumes wait behind long preparations leave nothing queued: each
// had left a pool job (and its entry) until a preparation thread was free, so a client sending
// view after view grew the daemon for as long as those preparations ran.
TEST(Catalogue, PreparationsGivenUpInLineLeaveNothingQueued) {
  CatalogueOptions o;
  o.prepare_delay = std::chrono::milliseconds(1500);
  VolumeCatalogue catalogue(o);
  std::vector<std::thread> running;
  for (const char* name : {"sphere:17", "cayley:17", "buckyball:17", "shells:17"})
    running.emplace_back([&catalogue, name] { EXPECT_TRUE(catalogue.Get(name).ok()); });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // on all four threads
  for (int i = 0; i < 200; ++i) {
    auto given_up = catalogue.Get("noise:17:" + std::to_string(i + 2), [] { return true; });
    EXPECT_EQ(given_up.status().code(), absl::StatusCode::kCancelled) << given_up.status();
  }
  EXPECT_EQ(catalogue.queued_preparations(), 0u);
  for (std::thread& t : running) t.join();
  EXPECT_EQ(catalogue.prepared_count(), 4);
  EXPECT_TRUE(catalogue.Get("noise:17:2").ok());  // asked again, it is prepared afresh
}

TEST(Quantization, AtMostOneSixtyFourthVoxel) {
  for (int n : {9, 65, 129, 513, 2049}) {
    Volume v;
    v.dims = {n, n / 2 + 1, n};
    v.spacing = {0.5, 0.25, 0.5};
    v.origin = {-3, 10, 0};
    QuantizationBox box;
    int bits;
    QuantizationFor(v, &box, &bits);
    EXPECT_LE(PositionErrorBound(box, bits), 0.25 / 64 * 1.01) << n;
    for (int a = 0; a < 3; ++a) {
      EXPECT_LT(box.origin[a], v.origin[a]);
      EXPECT_GT(box.origin[a] + box.range, v.origin[a] + v.spacing[a] * (v.dims[a] - 1));
    }
  }
}

// A stream's retained frame: recorded unless the stream slides through meshes, charged to the
// daemon's budget for what it holds, freed when the stream draws another mesh or the budget
// has no room, and never kept from a frame that did not finish.
// buckyball:65 served as the daemon serves it, and one request for two of its shells.
class RetainedFrameTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto volume = catalogue_.Get("buckyball:65");
    ASSERT_TRUE(volume.ok()) << volume.status();
    volume_ = *volume;
    r.isovalues = {0.05f, 0.15f};
    r.eps = 0.004;
    r.view.eye = {3, 2, 1};
  }
  // Extracts r, recording into `cut` if given; returns the triangle count. The frame stays in
  // `frame_`, for RetainedFrame::EndRecording.
  int64_t extract(RetainedCut* cut = nullptr) {
    auto res = Extract(*v().prepared.hierarchy, v().prepared.grid_to_world, r, nullptr, cut);
    EXPECT_TRUE(res.ok());
    if (!res.ok()) return 0;
    frame_ = std::move(res->mesh);
    return res->stats.triangles;
  }
  const ServedVolume& v() const { return *volume_; }

  VolumeCatalogue catalogue_{CatalogueOptions{}};
  ServedVolumePtr volume_;
  ExtractRequest r;
  OrderedMesh frame_;  // the last extraction's
};

TEST_F(RetainedFrameTest, RecordsKeepsAndFreesWithinTheBudget) {
  const ServedVolume& v = this->v();

  RetainBudget budget(int64_t{256} << 20);
  {
    RetainedFrame frame(&budget);
    RetainedCut* cut = frame.StartRecording(v, r);  // a session's first frame is recorded
    ASSERT_NE(cut, nullptr);
    const int64_t triangles = extract(cut);
    frame.EndRecording(v, &frame_);
    frame.Drew(v, r, triangles);
    ASSERT_NE(frame.Find(v, r), nullptr);
    EXPECT_EQ(budget.used(), int64_t(frame.Find(v, r)->memory_bytes()));
    EXPECT_GT(budget.used(), 32 * triangles);
    // The next frame of this size is estimated at what this one held, not less.
    EXPECT_GE(budget.Estimate(triangles), budget.used());

    // A frame that did not finish is not kept, and what was held stays charged until freed.
    ASSERT_NE(frame.StartRecording(v, r), nullptr);
    frame.EndRecording(v, nullptr);
    EXPECT_EQ(frame.Find(v, r), nullptr);
    EXPECT_GT(budget.used(), 0);

    // Another mesh drawn: the old one is freed.
    ExtractRequest other = r;
    other.eps = 0.008;
    frame.Drew(v, other, 1000);
    EXPECT_EQ(budget.used(), 0);
    EXPECT_EQ(frame.Find(v, r), nullptr);
    frame.Drew(v, r, triangles);
    cut = frame.StartRecording(v, r);
    ASSERT_NE(cut, nullptr);
    extract(cut);
    frame.EndRecording(v, &frame_);
    EXPECT_NE(frame.Find(v, r), nullptr);
  }
  EXPECT_EQ(budget.used(), 0);  // the stream's end gives everything back

  // No room in the budget: nothing is recorded, nothing stays charged.
  RetainBudget small(4096);
  RetainedFrame frame(&small);
  frame.Drew(v, r, 50000);
  EXPECT_EQ(frame.StartRecording(v, r), nullptr);
  EXPECT_EQ(small.used(), 0);
  // An estimate that fits but a frame that does not: the recording stops once its records
  // outgrow the budget, never holding much past it, and nothing is kept.
  int64_t tree = 0;
  {
    RetainBudget roomy(int64_t{1} << 40);
    RetainedFrame sizing(&roomy);
    RetainedCut* full = sizing.StartRecording(v, r);
    ASSERT_NE(full, nullptr);
    extract(full);
    tree = int64_t(full->tree_bytes());
  }
  RetainBudget tight(tree / 2);
  RetainedFrame tight_frame(&tight);
  tight_frame.Drew(v, r, 100);
  RetainedCut* cut = tight_frame.StartRecording(v, r);
  ASSERT_NE(cut, nullptr);
  extract(cut);
  EXPECT_LE(tight.used(), tight.limit());
  EXPECT_EQ(cut->tree_bytes(), 0u);  // released when refused room
  tight_frame.EndRecording(v, &frame_);
  EXPECT_EQ(tight_frame.Find(v, r), nullptr);
  EXPECT_EQ(tight.used(), 0);
}

// A stream sliding through meshes (each refined frame of another mesh than the one before)
// records nothing from its third mesh on; back on one mesh, it records again.
TEST_F(RetainedFrameTest, SlidingThroughMeshesRecordsNothing) {
  const ServedVolume& v = this->v();
  RetainBudget budget(int64_t{256} << 20);
  RetainedFrame frame(&budget);
  // Draws r at `eps` as FrameProducer does; true if the frame was recorded.
  auto draw = [&](double eps) {
    r.eps = eps;
    RetainedCut* cut = frame.StartRecording(v, r);
    const int64_t triangles = extract(cut);
    if (cut) frame.EndRecording(v, &frame_);
    frame.Drew(v, r, triangles);
    return cut != nullptr;
  };
  EXPECT_TRUE(draw(0.004));  // a session's first mesh
  EXPECT_TRUE(draw(0.005));  // one change: a new mesh to look around
  EXPECT_NE(frame.Find(v, r), nullptr);
  EXPECT_FALSE(draw(0.006));    // sliding
  EXPECT_EQ(budget.used(), 0);  // the last recorded mesh was freed
  EXPECT_FALSE(draw(0.007));
  EXPECT_TRUE(draw(0.007));  // the same mesh again: recorded, the next view is re-ordered
  EXPECT_NE(frame.Find(v, r), nullptr);
  EXPECT_TRUE(draw(0.004));  // a new mesh after a settled one
  EXPECT_NE(frame.Find(v, r), nullptr);
}

// When the budget has no room for a stream's frame, the least recently used frames of other
// streams are freed, unless their streams are using them right now.
TEST_F(RetainedFrameTest, FreesOtherStreamsFramesLeastRecentlyUsedFirst) {
  const ServedVolume& v = this->v();
  // Records a frame of r into `frame` (its second view of the mesh); true if it is kept.
  auto retain = [&](RetainedFrame& frame) {
    frame.Drew(v, r, extract());
    RetainedCut* cut = frame.StartRecording(v, r);
    if (cut == nullptr) return false;
    extract(cut);
    frame.EndRecording(v, &frame_);
    return frame.Find(v, r) != nullptr;
  };
  RetainedFrame probe(nullptr);  // no budget: never records
  EXPECT_FALSE(retain(probe));
  // Room for two frames of this mesh, not three.
  RetainBudget sizing(int64_t{1} << 40);
  int64_t one = 0;
  {
    RetainedFrame frame(&sizing);
    ASSERT_TRUE(retain(frame));
    one = sizing.used();
  }
  RetainBudget budget(one * 5 / 2);
  RetainedFrame a(&budget), b(&budget), c(&budget);
  ASSERT_TRUE(retain(a));
  ASSERT_TRUE(retain(b));
  a.Find(v, r);  // a is used again: b is now the least recently used
  ASSERT_TRUE(retain(c));
  EXPECT_NE(a.Find(v, r), nullptr);
  EXPECT_EQ(b.Find(v, r), nullptr);
  EXPECT_LE(budget.used(), budget.limit());
  // A frame no eviction could make room for frees nothing.
  RetainedFrame huge(&budget);
  huge.Drew(v, r, int64_t{1} << 32);  // its next frame is estimated past the whole budget
  EXPECT_EQ(huge.StartRecording(v, r), nullptr);
  EXPECT_NE(a.Find(v, r), nullptr);
  EXPECT_NE(c.Find(v, r), nullptr);
  // When the frames that could be freed are not enough, none is freed: with a in
  // use, a frame estimated at two of these cannot fit even without c, so c must stay.
  {
    std::lock_guard<std::mutex> using_a_only(a.mutex());
    RetainedFrame d(&budget);
    d.Drew(v, r, 2 * extract());
    EXPECT_EQ(d.StartRecording(v, r), nullptr);
    EXPECT_NE(c.Find(v, r), nullptr);
  }
  // A frame whose stream is using it is not freed: with a and c in use, b finds no room.
  std::lock_guard<std::mutex> using_a(a.mutex());
  std::lock_guard<std::mutex> using_c(c.mutex());
  EXPECT_FALSE(retain(b));
  EXPECT_NE(a.Find(v, r), nullptr);
  EXPECT_NE(c.Find(v, r), nullptr);
  // The same volume prepared again (another catalogue: another hierarchy, the
  // first still alive) is another mesh: a's frame must not serve it.
  {
    VolumeCatalogue other{CatalogueOptions{}};
    auto again = other.Get("buckyball:65");
    ASSERT_TRUE(again.ok());
    ASSERT_NE((*again)->prepared.hierarchy, v.prepared.hierarchy);
    EXPECT_EQ(a.Find(**again, r), nullptr);
  }
}

}  // namespace
}  // namespace isostream::service
