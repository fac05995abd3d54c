// Integration tests of what isostreamd refuses at start (flags it would misread, a busy port,
// TLS files that cannot serve) and of serving over TLS. Each starts its own daemon on
// 127.0.0.1 (daemon_fixture.h); every wait is bounded.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/common/run_command.h"
#include "tests/integration/daemon_fixture.h"

// In the fixture's namespace, as daemon_options_test.cpp.
namespace isostream::testing {
namespace {

// Flags it would have to misread stop isostreamd before it listens, exit 2 and say why.
TEST(DaemonFlags, ThoseItWouldMisreadStopItAtStart) {
  const std::string first_chunk_config = ::testing::TempDir() + "/first_chunk.json";
  std::ofstream(first_chunk_config) << R"({"frames": {"first_chunk_triangles": 8000}})";
  const std::string default_first_chunk_config = ::testing::TempDir() + "/default_first_chunk.json";
  std::ofstream(default_first_chunk_config) << R"({"frames": {"first_chunk_triangles": 8192}})";
  const std::pair<std::string, std::string> refused[] = {
      {"--volume a=sphere:9 --volume a=cayley:9", "--volume names 'a' twice"},
      // Catalogue specs wrong as written (they started, and failed every request).
      {"--volume a=cayley:5l3", "volume 'a': generator spec 'cayley:5l3'"},
      {"--volume b=raw:x.raw:4x4:float32", "volume 'b': "},
      {"--volume c=notes.txt", "volume 'c': notes.txt: unrecognised volume type"},
      {"--listen 127.0.0.1:70000", "port in 0..65535"},
      {"--log-level shouty", "log_level (--log-level) must be one of"},
      {"--deadline-ms 10000000000000", "deadline_ms (--deadline-ms) must be in 1..86400000"},
      // A first chunk that was set is checked, not cut down to the chunk size.
      {"--chunk-triangles 4096 --config " + first_chunk_config,
       "first_chunk_triangles must be in 256..chunk_triangles"},
      // The default's value too, when it was written (it was cut as if left out).
      {"--chunk-triangles 4096 --config " + default_first_chunk_config,
       "first_chunk_triangles must be in 256..chunk_triangles"},
      // Named as the flag too, not only as the config key.
      {"--max-sessions 2000000000", "max_sessions (--max-sessions) must be in 1..4096"},
      {"--generator-mb 0", "generator_mb (--generator-mb) must be in 1..1073741824"},
      {"--max-dim 1026", "max_dim (--max-dim) must be in 2..1025"},
      // Counts take exponents (GuardedDaemon starts with --max-triangles 1e5), not fractions.
      {"--max-triangles 2.5", "--max-triangles: 2.5 is not a whole number"},
      {"--token ''", "--token is empty"},
      {"--token \"$(printf 'a\\tb')\"", "token must be printable ASCII"},
      {"--token ' s3cret'", "token must not start or end with a space"},
      {"--bogus", "--bogus"}};
  for (const auto& [flags, reason] : refused) {
    const CommandResult r =
        RunCommand(std::string("timeout 20 ") + ::isostream::testing::ShellQuote(ISOSTREAMD_PATH) +
                   " --no-cache " + flags);
    EXPECT_EQ(r.code, 2) << flags << "\n" << r.output;
    EXPECT_NE(r.output.find(reason), std::string::npos) << flags << "\n" << r.output;
  }
}

// --help is the daemon's output: written, exit 0; unwritable (a full disk), exit 1, as the CLI's.
TEST(DaemonFlags, HelpThatCannotBeWrittenExitsOne) {
  const std::string daemon = std::string("timeout 20 ") + ShellQuote(ISOSTREAMD_PATH);
  EXPECT_EQ(RunCommand(daemon + " --help >/dev/null").code, 0);
  // (RunCommand adds 2>&1 after the command: braces keep stderr on the pipe.)
  const CommandResult full = RunCommand("{ " + daemon + " --help >/dev/full; }");
  EXPECT_EQ(full.code, 1) << full.output;
  EXPECT_NE(full.output.find("cannot write standard output"), std::string::npos) << full.output;
}

// A daemon that cannot serve as asked stops at start, saying why: a port another daemon holds
// (exit 1: gRPC's default SO_REUSEPORT would have let both listen and split the clients
// between them), and TLS files that cannot serve (exit 2; gRPC blamed the port for those).
TEST(DaemonStart, RefusesABusyPortAndFilesThatAreNotPem) {
  ScratchDir dir;
  DaemonProcess first;
  ASSERT_TRUE(first.Start({"--no-cache"}, dir.path() + "/first.log"));
  CommandResult r =
      RunCommand(std::string("timeout 20 ") + ::isostream::testing::ShellQuote(ISOSTREAMD_PATH) +
                 " --no-cache --listen " + first.address());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot listen on " + first.address() + ": the port is in use"),
            std::string::npos)
      << r.output;
  // That line alone, without gRPC's nested error dump before it.
  EXPECT_EQ(r.output.find("chttp2"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_EQ(first.Stop(SIGTERM), 0);
  // An address of no interface here (TEST-NET-1: binding it sends nothing) is told apart from
  // a busy port: both were "the port is in use, or the address is not this machine's".
  r = RunCommand(std::string("timeout 20 ") + ::isostream::testing::ShellQuote(ISOSTREAMD_PATH) +
                 " --no-cache --listen 192.0.2.1:0");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot listen on 192.0.2.1:0: the address is not this machine's"),
            std::string::npos)
      << r.output;

  const std::string junk = dir.path() + "/junk.pem";
  { std::ofstream(junk) << "not a certificate\n"; }
  std::string key, cert;
  const bool have_pair = MakeTestCertificate(dir.path(), &key, &cert);
  const std::string base = std::string("timeout 20 ") +
                           ::isostream::testing::ShellQuote(ISOSTREAMD_PATH) +
                           " --no-cache --listen 127.0.0.1:0 ";
  // Files that cannot serve are configuration errors (exit 2: a service manager does not retry
  // them).
  r = RunCommand(base + "--tls-cert " + dir.path() + "/absent.pem --tls-key " + dir.path() +
                 "/absent.key");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("cannot read TLS key"), std::string::npos) << r.output;
  r = RunCommand(base + "--tls-cert " + junk + " --tls-key " + (have_pair ? key : junk));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("TLS certificate '" + junk + "' holds no PEM certificate"),
            std::string::npos)
      << r.output;
  if (!have_pair) GTEST_SKIP() << "openssl cannot make a test certificate";
  r = RunCommand(base + "--tls-cert " + cert + " --tls-key " + junk);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("TLS key '" + junk + "' holds no PEM private key"), std::string::npos)
      << r.output;
  // A certificate with another pair's key: named, exit 2 (gRPC failed only the listen, which
  // blamed the port and was retried as a failure to listen).
  const std::string other = dir.path() + "/other";
  ASSERT_TRUE(std::filesystem::create_directory(other));
  std::string other_key, other_cert;
  ASSERT_TRUE(MakeTestCertificate(other, &other_key, &other_cert));
  r = RunCommand(base + "--tls-cert " + cert + " --tls-key " + other_key);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(
      r.output.find("TLS key '" + other_key + "' does not belong to certificate '" + cert + "'"),
      std::string::npos)
      << r.output;
}

class TlsDaemon : public Daemon {};

TEST_F(TlsDaemon, ServesOverTls) {
  ScratchDir dir;
  std::string key, cert;
  if (!MakeTestCertificate(dir.path(), &key, &cert))
    GTEST_SKIP() << "openssl cannot make a test certificate";
  DaemonProcess tls;
  ASSERT_TRUE(tls.Start({"--tls-cert", cert, "--tls-key", key, "--no-cache"},
                        dir.path() + "/isostreamd.log"));
  auto pem = net::ReadTlsCa(cert);
  ASSERT_TRUE(pem.ok()) << pem.status();
  net::ClientOptions o;
  o.address = tls.address();
  o.tls_ca_pem = *pem;
  auto secure = net::Client::Connect(o);
  ASSERT_TRUE(secure.ok());
  auto frame = (*secure)->Fetch(MakeView("buckyball:65", 1, 0.05, glm::dvec3(2, 2, 2)));
  EXPECT_TRUE(frame.ok()) << frame.status();
  o.tls_ca_pem.clear();
  o.call_timeout = std::chrono::milliseconds(2000);
  auto plain = net::Client::Connect(o);
  ASSERT_TRUE(plain.ok());
  const auto refused = (*plain)->ListVolumes();
  ASSERT_FALSE(refused.ok());
  // gRPC says only "failed to connect": the explanation names TLS.
  EXPECT_NE(net::ExplainCallError(refused.status(), o).find("--tls-ca"), std::string::npos)
      << refused.status();
  EXPECT_EQ(tls.Stop(SIGTERM), 0);
}

}  // namespace
}  // namespace isostream::testing
