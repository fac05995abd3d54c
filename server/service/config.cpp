#include "server/service/config.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <type_traits>

#include "server/volume/volume_spec.h"
#include "shared/frame_codec.h"
#include "shared/number_list.h"
#include "shared/printable_text.h"

namespace isostream::service {
namespace {

using nlohmann::json;

absl::Status CheckKeys(const json& object, const std::set<std::string>& known,
                       const std::string& where) {
  if (!object.is_object()) {
    // `where` is the key's prefix ("tls."), empty for the whole file.
    const std::string what =
        where.empty() ? "the configuration" : "'" + where.substr(0, where.size() - 1) + "'";
    return absl::InvalidArgumentError(what + " must be a JSON object");
  }
  for (auto it = object.begin(); it != object.end(); ++it)
    if (!known.count(it.key()))
      return absl::InvalidArgumentError("unknown key '" + where + it.key() + "'");
  return absl::OkStatus();
}

// Reads object[key] into *out when present; a wrong type names the key. An integer setting
// takes whole numbers in its type's range only (2.5 or 1e20 would otherwise be cut or wrap).
template <class T>
absl::Status Get(const json& object, const char* key, const std::string& where, T* out) {
  auto it = object.find(key);
  if (it == object.end()) return absl::OkStatus();
  if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
    // A whole number written with a fraction or an exponent (1e3, 30000.0) is one too.
    const double d = it->is_number_float() ? it->get<double>() : 0.0;
    const bool whole_float = it->is_number_float() && std::trunc(d) == d &&
                             d >= double(std::numeric_limits<T>::min()) &&
                             // max + 1 is a power of two, exact in double (max itself may round
                             // up to it, and converting that is undefined)
                             d < double(std::numeric_limits<T>::max()) + 1.0;
    const bool fits =
        it->is_number_unsigned()  ? it->get<uint64_t>() <= uint64_t(std::numeric_limits<T>::max())
        : it->is_number_integer() ? it->get<int64_t>() >= int64_t(std::numeric_limits<T>::min()) &&
                                        it->get<int64_t>() <= int64_t(std::numeric_limits<T>::max())
                                  : whole_float;
    if (it->is_number() && !fits)
      return absl::InvalidArgumentError("'" + where + key + "' must be a whole number in " +
                                        std::to_string(std::numeric_limits<T>::min()) + ".." +
                                        std::to_string(std::numeric_limits<T>::max()));
    if (whole_float) {
      *out = T(d);
      return absl::OkStatus();
    }
  }
  try {
    *out = it->get<T>();
  } catch (const json::exception&) {
    return absl::InvalidArgumentError("'" + where + key + "' has the wrong type");
  }
  return absl::OkStatus();
}

absl::Status Parse(const json& j, DaemonConfig* c) {
  ISOSTREAM_RETURN_IF_ERROR(
      CheckKeys(j,
                {"listen", "threads", "cache_dir", "no_cache", "cache_max_mb", "volumes", "preload",
                 "token", "tls", "limits", "frames", "log_level", "shutdown_grace_ms"},
                ""));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "listen", "", &c->listen));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "threads", "", &c->threads));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "cache_dir", "", &c->cache_dir));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "no_cache", "", &c->no_cache));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "cache_max_mb", "", &c->cache_max_mb));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "volumes", "", &c->volumes));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "preload", "", &c->preload));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "token", "", &c->token));
  // An empty one (a template's placeholder, say) would serve without a token, silently.
  if (j.contains("token") && c->token.empty())
    return absl::InvalidArgumentError("'token' is empty; leave it out to serve without a token");
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "log_level", "", &c->log_level));
  ISOSTREAM_RETURN_IF_ERROR(Get(j, "shutdown_grace_ms", "", &c->shutdown_grace_ms));
  if (j.contains("tls")) {
    const json& t = j["tls"];
    ISOSTREAM_RETURN_IF_ERROR(CheckKeys(t, {"cert", "key"}, "tls."));
    ISOSTREAM_RETURN_IF_ERROR(Get(t, "cert", "tls.", &c->tls_cert));
    ISOSTREAM_RETURN_IF_ERROR(Get(t, "key", "tls.", &c->tls_key));
  }
  if (j.contains("limits")) {
    const json& l = j["limits"];
    ISOSTREAM_RETURN_IF_ERROR(
        CheckKeys(l,
                  {"max_sessions", "max_triangles", "max_isovalues", "deadline_ms", "max_dim",
                   "generator_mb", "idle_timeout_s"},
                  "limits."));
    ISOSTREAM_RETURN_IF_ERROR(Get(l, "max_sessions", "limits.", &c->limits.max_sessions));
    ISOSTREAM_RETURN_IF_ERROR(Get(l, "max_triangles", "limits.", &c->limits.max_triangles));
    ISOSTREAM_RETURN_IF_ERROR(Get(l, "max_isovalues", "limits.", &c->limits.max_isovalues));
    ISOSTREAM_RETURN_IF_ERROR(Get(l, "deadline_ms", "limits.", &c->limits.deadline_ms));
    ISOSTREAM_RETURN_IF_ERROR(Get(l, "max_dim", "limits.", &c->limits.max_dim));
    ISOSTREAM_RETURN_IF_ERROR(Get(l, "generator_mb", "limits.", &c->limits.generator_mb));
    ISOSTREAM_RETURN_IF_ERROR(Get(l, "idle_timeout_s", "limits.", &c->limits.idle_timeout_s));
  }
  if (j.contains("frames")) {
    const json& f = j["frames"];
    ISOSTREAM_RETURN_IF_ERROR(CheckKeys(f,
                                        {"chunk_triangles", "first_chunk_triangles",
                                         "coarse_triangles", "max_queued_chunks", "retain_mb"},
                                        "frames."));
    ISOSTREAM_RETURN_IF_ERROR(Get(f, "chunk_triangles", "frames.", &c->chunk_triangles));
    if (f.contains("first_chunk_triangles")) {
      int first = 0;
      ISOSTREAM_RETURN_IF_ERROR(Get(f, "first_chunk_triangles", "frames.", &first));
      c->first_chunk_triangles = first;
    }
    ISOSTREAM_RETURN_IF_ERROR(Get(f, "coarse_triangles", "frames.", &c->coarse_triangles));
    ISOSTREAM_RETURN_IF_ERROR(Get(f, "max_queued_chunks", "frames.", &c->max_queued_chunks));
    ISOSTREAM_RETURN_IF_ERROR(Get(f, "retain_mb", "frames.", &c->retain_mb));
  }
  return absl::OkStatus();
}

// Where and why `text` is not JSON, from the parser's exception (the non-throwing parse says
// only that it failed): "'x.json' is not valid JSON: parse error at line 3, column 5: ...".
std::string JsonError(const std::string& path, const std::string& text) {
  std::string why;
  try {
    const json parsed = json::parse(text);  // throws where the non-throwing parse failed
    (void)parsed;
  } catch (const json::exception& e) {  // parse errors, and numbers past double (1e400)
    why = e.what();
    // "[json.exception.parse_error.101] parse error at ...": the bracketed id means nothing to
    // whoever wrote the file.
    if (const size_t id_end = why.find("] ");
        why.rfind("[json.", 0) == 0 && id_end != std::string::npos)
      why.erase(0, id_end + 2);
  } catch (const std::exception& e) {
    why = e.what();
  }
  return "'" + path + "' is not valid JSON" + (why.empty() ? "" : ": " + why);
}

// A relative path in a config file is the file's: a daemon's working directory is rarely where
// its config lives (systemd's is /), and "data/ct.nii.gz" failed there at every preparation.
std::string Beside(const std::filesystem::path& dir, const std::string& path) {
  if (path.empty() || std::filesystem::path(path).is_absolute()) return path;
  return (dir / path).string();
}

// The same for a catalogue spec naming a file (a generator names none): the whole spec for a
// .vdb (its "#GRID" stays a suffix), NIfTI or raw file, the PATH part of "raw:PATH:...".
std::string SpecBeside(const std::filesystem::path& dir, const std::string& spec) {
  const auto parsed = ParseVolumeSpec(spec, VolumeLimits{});
  if (!parsed.ok() || parsed->source == VolumeSource::kGenerator) return spec;  // checked later
  if (parsed->source == VolumeSource::kRawFile) {
    constexpr std::string_view kRaw = "raw:";
    return std::string(kRaw) + Beside(dir, spec.substr(kRaw.size()));
  }
  return Beside(dir, spec);
}

absl::Status ReadConfigFile(const std::string& path, DaemonConfig* config) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    return absl::InvalidArgumentError("config file '" + path + "' is a directory");
  std::ifstream in(path);
  if (!in)  // why, too: a service's user may lack the permission an admin's shell has
    return absl::NotFoundError("cannot open config file '" + path + "': " + std::strerror(errno));
  std::stringstream text;
  text << in.rdbuf();
  // A key given twice in one object would silently keep its last value: refused, named.
  std::vector<std::set<std::string>> open_objects;
  std::string repeated;
  const json::parser_callback_t note_keys = [&](int /*depth*/, json::parse_event_t event,
                                                json& parsed) {
    if (event == json::parse_event_t::object_start) open_objects.emplace_back();
    if (event == json::parse_event_t::object_end && !open_objects.empty()) open_objects.pop_back();
    if (event == json::parse_event_t::key && !open_objects.empty() && repeated.empty() &&
        !open_objects.back().insert(parsed.get<std::string>()).second)
      repeated = parsed.get<std::string>();
    return true;
  };
  const json j = json::parse(text.str(), note_keys, /*allow_exceptions=*/false);
  if (j.is_discarded()) return absl::InvalidArgumentError(JsonError(path, text.str()));
  if (!repeated.empty())
    return absl::InvalidArgumentError(path + ": key '" + repeated + "' is given twice");
  const absl::Status s = Parse(j, config);
  if (!s.ok()) return absl::InvalidArgumentError(path + ": " + std::string(s.message()));
  std::error_code failed;
  const std::filesystem::path whole = std::filesystem::absolute(path, failed);
  const std::filesystem::path dir = (failed ? std::filesystem::path(path) : whole).parent_path();
  for (auto& [name, spec] : config->volumes) spec = SpecBeside(dir, spec);
  config->cache_dir = Beside(dir, config->cache_dir);
  config->tls_cert = Beside(dir, config->tls_cert);
  config->tls_key = Beside(dir, config->tls_key);
  return absl::OkStatus();
}

}  // namespace

int FirstChunkTriangles(const DaemonConfig& c) {
  return c.first_chunk_triangles.value_or(std::min(kDefaultFirstChunkTriangles, c.chunk_triangles));
}

absl::Status LoadConfigFile(const std::string& path, DaemonConfig* config) {
  const absl::Status read = ReadConfigFile(path, config);
  if (read.ok()) return read;
  // Messages quote the file (keys, values, the bytes a parse stopped at): printed escaped, as
  // a volume's load errors are.
  const absl::string_view message = read.message();
  return absl::Status(read.code(), PrintableText(std::string_view(message.data(), message.size())));
}

absl::Status ValidateConfig(const DaemonConfig& c) {
  auto bad = [](const std::string& m) { return absl::InvalidArgumentError(m); };
  // A key that is also a flag is named both ways: a user who typed --max-sessions 0 should not
  // have to guess that max_sessions is it.
  auto key = [](std::string k) {
    std::string flag = "--" + k;
    std::replace(flag.begin(), flag.end(), '_', '-');
    return k + " (" + flag + ")";
  };
  if (c.threads < 0 || c.threads > 1024) return bad(key("threads") + " must be in 0..1024");
  // Each admissible session has a frame thread of its own, started with the daemon.
  if (c.limits.max_sessions < 1 || c.limits.max_sessions > 4096)
    return bad(key("max_sessions") + " must be in 1..4096");
  if (c.cache_max_mb < 1 || c.cache_max_mb > (int64_t{1} << 30))
    return bad(key("cache_max_mb") + " must be in 1..1073741824");
  if (c.limits.max_triangles < 1) return bad(key("max_triangles") + " must be at least 1");
  if (c.limits.max_isovalues < 1 || c.limits.max_isovalues > 16)
    return bad(key("max_isovalues") + " must be in 1..16");
  // A day at most: far past any frame, and clock arithmetic overflowed past ~292 years (every
  // frame then failed at once).
  if (c.limits.deadline_ms < 1 || c.limits.deadline_ms > 86'400'000)
    return bad(key("deadline_ms") + " must be in 1..86400000");
  // A volume is held as a 2^k+1 cube of at most 1025^3 points (its longest side cubed): a larger
  // side could never be prepared.
  if (c.limits.max_dim < 2 || c.limits.max_dim > 1025)
    return bad(key("max_dim") + " must be in 2..1025");
  if (c.limits.generator_mb < 1 || c.limits.generator_mb > (int64_t{1} << 30))
    return bad(key("generator_mb") + " must be in 1..1073741824");
  if (c.limits.idle_timeout_s < 0 || c.limits.idle_timeout_s > 7 * 86400)
    return bad(key("idle_timeout_s") + " must be in 0 (off)..604800");
  if (c.tls_cert.empty() != c.tls_key.empty()) return bad("TLS needs both a certificate and a key");
  // A catalogue entry wrong as written (an unknown generator, a malformed raw layout, a file
  // type no loader reads) would fail on every request, retried every 30 s: refused at start.
  // Files are not opened here: a missing or damaged one may be put right while serving.
  for (const auto& [name, spec] : c.volumes) {
    const auto parsed = ParseVolumeSpec(spec, VolumeLimits{});
    if (!parsed.ok())
      return bad("volume '" + name + "': " + std::string(parsed.status().message()));
  }
  // What a client can send in a header value (gRPC refuses the rest, so no call could pass).
  for (const char ch : c.token)
    if (ch < 0x20 || ch > 0x7e)
      return bad("token must be printable ASCII (no control or non-ASCII characters)");
  // A header value loses the spaces around it on its way (and the check skips those after
  // "Bearer"), so such a token could never be presented: every call would be refused.
  if (!c.token.empty() && (c.token.front() == ' ' || c.token.back() == ' '))
    return bad("token must not start or end with a space (no client could present it)");
  // Chunks must stay under gRPC's 4 MiB message limit: a Draco chunk needs at most about 40
  // bytes per triangle (no shared vertices, indices stored plainly); raw chunks are cut at
  // kMaxRawChunkTriangles regardless.
  if (c.chunk_triangles < 256 || c.chunk_triangles > int(kMaxStreamChunkTriangles))
    return bad(key("chunk_triangles") + " must be in 256.." +
               std::to_string(kMaxStreamChunkTriangles));
  if (c.first_chunk_triangles &&
      (*c.first_chunk_triangles < 256 || *c.first_chunk_triangles > c.chunk_triangles))
    return bad("first_chunk_triangles must be in 256..chunk_triangles (" +
               std::to_string(c.chunk_triangles) + "), got " +
               std::to_string(*c.first_chunk_triangles));
  if (c.coarse_triangles < 100) return bad("coarse_triangles must be at least 100");
  if (c.max_queued_chunks < 2 || c.max_queued_chunks > 256)
    return bad("max_queued_chunks must be in 2..256");
  if (c.retain_mb < 0 || c.retain_mb > (int64_t{1} << 30))
    return bad(key("retain_mb") + " must be in 0 (off)..1073741824");
  for (const auto& [name, spec] : c.volumes)
    if (name.empty() || spec.empty()) return bad("catalogue names and specs must not be empty");
  if (c.shutdown_grace_ms < 0 || c.shutdown_grace_ms > 3'600'000)
    return bad("shutdown_grace_ms must be in 0..3600000");
  static const std::set<std::string> kLevels = {"trace", "debug",    "info", "warn",
                                                "error", "critical", "off"};
  if (!kLevels.count(c.log_level))
    return bad(key("log_level") +
               " must be one of trace, debug, info, warn, error, critical, off; got '" +
               c.log_level + "'");
  if (!CheckPort(c.listen, /*required=*/true).ok())
    return bad(key("listen") + " must be HOST:PORT with a port in 0..65535; got '" + c.listen +
               "'");
  return absl::OkStatus();
}

}  // namespace isostream::service
