// isostreamd's JSON config: what is read, what is refused and why, and paths relative to the file.
#include "server/service/config.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include "tests/integration/daemon_process.h"

namespace isostream::service {
namespace {

using testing::ScratchDir;

absl::Status LoadText(const std::string& text, DaemonConfig* c) {
  ScratchDir dir;
  const std::string path = dir.path() + "/c.json";
  std::ofstream(path) << text;
  return LoadConfigFile(path, c);
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

}  // namespace
}  // namespace isostream::service
