// isostreamd's settings: defaults here, then the JSON config file, then command-line flags.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "shared/status.h"

namespace isostream::service {

struct Limits {
  int max_sessions = 16;              // concurrent Session and Extract streams
  int64_t max_triangles = 4'000'000;  // per frame
  int max_isovalues = 16;
  int64_t deadline_ms = 30'000;  // per frame's extraction; also a client's longest silence
  int max_dim = 257;             // samples per axis of a generator served without a catalogue
  // Memory for the generated volumes held at once (their hierarchy stores: 105 MiB at 257^3,
  // 6.1 GiB at 1025^3, 921 MiB for sphere:514, which stores stand-ins for most of its 1025^3
  // cube); catalogue.h says how it is kept.
  int64_t generator_mb = 8192;
  // A Session with no view request and nothing in flight for this long is ended by the server
  // with DEADLINE_EXCEEDED, freeing its slot and memory; 0 = never.
  int64_t idle_timeout_s = 300;
};

struct DaemonConfig {
  std::string listen = "127.0.0.1:7878";
  int threads = 0;        // extraction threads per frame and encoder threads; 0: all cores
  std::string cache_dir;  // empty: the default cache directory
  bool no_cache = false;
  // The cache keeps at most this much (least recently used entries go first): clients name
  // the generated volumes it stores, so without a cap they could fill the disk.
  int64_t cache_max_mb = 16384;
  Limits limits;
  // Catalogue: name -> volume spec (generator, .vdb, .nii, raw:...). Clients see names only.
  std::map<std::string, std::string> volumes;
  // Prepare every catalogue volume at start, one after another in the background, so the
  // first view of each does not wait for its load and hierarchy (requests meanwhile share the
  // preparation in progress). Catalogue volumes stay prepared once used anyway.
  bool preload = true;
  std::string tls_cert, tls_key;  // PEM files; both or neither
  std::string token;              // bearer token; empty: no auth
  // Frames are cut into chunks of at most this many triangles; the first chunks of a frame are
  // smaller (first_chunk_triangles, doubling) so that the first one leaves early.
  int chunk_triangles = 65536;
  // Unset, it is kDefaultFirstChunkTriangles, or chunk_triangles when that is smaller (see
  // FirstChunkTriangles). Kept unset rather than holding the default so that a value someone
  // wrote, the default's own included, is checked against chunk_triangles and not cut to it.
  std::optional<int> first_chunk_triangles;
  int coarse_triangles = 20000;  // budget of the coarse frame of a progressive request
  int max_queued_chunks = 8;     // per stream: encoded or encoding, not yet written
  // Each stream keeps its last refined frame's cut, so a new view of the same mesh is
  // re-ordered instead of extracted (~56 MB per 1 M triangles); all streams together keep at
  // most this much (a frame that does not fit is not kept). 0: keep none.
  int64_t retain_mb = 1024;
  int shutdown_grace_ms = 5000;  // how long SIGTERM waits for frames in flight
  std::string log_level = "info";
};

inline constexpr int kDefaultFirstChunkTriangles = 8192;

// The first chunk's size frames are cut with: the one set, else the default within
// chunk_triangles.
int FirstChunkTriangles(const DaemonConfig& config);

// Reads a JSON config file over `config` (keys absent from the file keep their value):
//   {"listen": "127.0.0.1:7878", "threads": 2, "cache_dir": "/var/cache/isostream",
//    "cache_max_mb": 16384,
//    "volumes": {"head": "/data/head.nii.gz"}, "preload": true, "token": "...",
//    "tls": {"cert": "server.pem", "key": "server.key"},
//    "limits": {"max_sessions": 16, "max_triangles": 4000000, "max_isovalues": 16,
//               "deadline_ms": 30000, "max_dim": 257, "generator_mb": 8192,
//               "idle_timeout_s": 300},
//    "frames": {"chunk_triangles": 65536, "first_chunk_triangles": 8192,
//               "coarse_triangles": 20000, "max_queued_chunks": 8, "retain_mb": 1024},
//    "log_level": "info"}
// Unknown keys and wrong types are errors naming the key.
absl::Status LoadConfigFile(const std::string& path, DaemonConfig* config);

// Range checks after all sources are merged.
absl::Status ValidateConfig(const DaemonConfig& config);

}  // namespace isostream::service
