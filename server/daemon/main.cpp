// isostreamd: serves view-ordered, Draco-compressed isosurface frames over gRPC.
//
// Settings come from defaults, then --config FILE.json, then flags. It listens on 127.0.0.1
// unless told otherwise, prints "listening on HOST:PORT" on stdout once it accepts calls (port
// 0 picks a free port), and on SIGINT/SIGTERM/SIGHUP turns its health status to NOT_SERVING,
// refuses new streams, ends views still waiting for a volume's preparation (UNAVAILABLE) and
// stops that preparation, lets frames in flight finish (bounded wait) and exits 0, without
// waiting more than a second for a preparation that cannot stop mid-step.
#include <google/protobuf/stubs/logging.h>
#include <grpc/support/log.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/security/server_credentials.h>
#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

#include "server/daemon/listen_failure.h"
#include "server/service/config.h"
#include "server/service/service.h"
#include "shared/file_io.h"
#include "shared/given_number.h"
#include "shared/malloc_tuning.h"

namespace {

using isostream::service::DaemonConfig;

// The signals that stop the daemon gracefully. SIGHUP too: a closing terminal sends it, and its
// default action ended the process at once, cutting frames in flight; but not when it was
// ignored at start (nohup), since a blocked signal is queued for sigwait even then.
sigset_t StopSignals() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  struct sigaction hangup;
  if (sigaction(SIGHUP, nullptr, &hangup) != 0 || hangup.sa_handler != SIG_IGN)
    sigaddset(&signals, SIGHUP);
  return signals;
}

bool ReadFile(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::stringstream s;
  s << in.rdbuf();
  *out = s.str();
  return true;
}

// protobuf's own messages (one per request whose string field is not UTF-8, say) went to
// stderr unformatted, so any client could flood the log: they go to the log at debug level (the
// client already gets INVALID_ARGUMENT for such a request).
void ProtobufLog(google::protobuf::LogLevel level, const char* file, int line,
                 const std::string& message) {
  if (level >= google::protobuf::LOGLEVEL_FATAL)
    spdlog::critical("protobuf {}:{}: {}", file, line, message);
  else
    spdlog::debug("protobuf {}:{}: {}", file, line, message);
}

// gRPC's own messages went to stderr raw: a port in use printed a nested error dump before the
// daemon's one line saying so, and a client speaking plaintext to a TLS port logs a handshake
// error per attempt, so any client could flood the log. They go to the log at debug level, as
// protobuf's do: what fails for the daemon or a caller it says itself.
void GrpcLog(gpr_log_func_args* args) {
  spdlog::debug("grpc {}:{}: {}", args->file, args->line, args->message);
}

// Whether the PEM key is the private half of the PEM certificate's public key; nullopt where
// either does not parse here (gRPC then decides). gRPC tells a pair that does not belong
// together only as a failed listen, blaming the port, after the catalogue's preparation began.
std::optional<bool> KeyBelongsToCertificate(const std::string& key, const std::string& cert) {
  // No passphrase prompt on the terminal for an encrypted key (gRPC takes none either).
  pem_password_cb* no_passphrase = [](char*, int, int, void*) { return 0; };
  std::unique_ptr<BIO, decltype(&BIO_free)> key_in(BIO_new_mem_buf(key.data(), int(key.size())),
                                                   &BIO_free);
  std::unique_ptr<BIO, decltype(&BIO_free)> cert_in(BIO_new_mem_buf(cert.data(), int(cert.size())),
                                                    &BIO_free);
  if (!key_in || !cert_in) return std::nullopt;
  std::unique_ptr<EVP_PKEY, decltype(&EVP_PKEY_free)> private_key(
      PEM_read_bio_PrivateKey(key_in.get(), nullptr, no_passphrase, nullptr), &EVP_PKEY_free);
  std::unique_ptr<X509, decltype(&X509_free)> certificate(
      PEM_read_bio_X509(cert_in.get(), nullptr, no_passphrase, nullptr), &X509_free);
  ERR_clear_error();  // what failed to parse is gRPC's to report
  if (!private_key || !certificate) return std::nullopt;
  const bool belongs = X509_check_private_key(certificate.get(), private_key.get()) == 1;
  ERR_clear_error();
  return belongs;
}

int Run(const DaemonConfig& config) {
  std::shared_ptr<grpc::ServerCredentials> creds;
  if (!config.tls_cert.empty()) {
    grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
    if (!ReadFile(config.tls_key, &pair.private_key) ||
        !ReadFile(config.tls_cert, &pair.cert_chain)) {
      spdlog::critical("cannot read TLS key '{}' or certificate '{}'", config.tls_key,
                       config.tls_cert);
      return 2;  // a configuration error, as a bad flag: restarting would not mend it
    }
    // gRPC reports a file that is not PEM only as a failure to listen, blaming the port.
    if (pair.cert_chain.find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
      spdlog::critical("TLS certificate '{}' holds no PEM certificate", config.tls_cert);
      return 2;
    }
    if (pair.private_key.find("PRIVATE KEY-----") == std::string::npos) {
      spdlog::critical("TLS key '{}' holds no PEM private key", config.tls_key);
      return 2;
    }
    if (KeyBelongsToCertificate(pair.private_key, pair.cert_chain) == false) {
      spdlog::critical("TLS key '{}' does not belong to certificate '{}'", config.tls_key,
                       config.tls_cert);
      return 2;
    }
    grpc::SslServerCredentialsOptions options;
    options.pem_key_cert_pairs.push_back(pair);
    creds = grpc::SslServerCredentials(options);
  } else {
    creds = grpc::InsecureServerCredentials();
    if (config.listen.rfind("127.", 0) != 0 && config.listen.rfind("localhost", 0) != 0 &&
        config.listen.rfind("[::1]", 0) != 0)
      spdlog::warn("listening on {} without TLS", config.listen);
  }

  grpc::EnableDefaultHealthCheckService(true);
  isostream::service::IsostreamService service(config);
  grpc::ServerBuilder builder;
  int port = 0;
  builder.AddListeningPort(config.listen, creds, &port);
  builder.RegisterService(&service);
  // Requests are small; frames go out in chunks below gRPC's default 4 MiB limit.
  builder.SetMaxReceiveMessageSize(1 << 20);
  builder.SetMaxSendMessageSize(4 << 20);
  // Pings find clients that vanished without closing their connection (a laptop lid, a cut
  // cable), so their sessions are freed instead of holding a slot until the process restarts.
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 60'000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 20'000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  // gRPC binds with SO_REUSEPORT by default: a second daemon on a busy port would start and
  // take a share of its connections (clients then meet the other's catalogue at random).
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (!server || port == 0) {
    const std::string reason = isostream::daemon::ListenFailureReason(config.listen);
    if (!reason.empty()) {
      spdlog::critical("cannot listen on {}: {}", config.listen, reason);
    } else {
      spdlog::critical(
          "cannot listen on {}: the port is in use, or the address is not this machine's{}",
          config.listen,
          config.tls_cert.empty() ? "" : ", or gRPC refused the TLS certificate or key");
    }
    return 1;
  }
  // Health checks that name the service (as Kubernetes' gRPC probes may) see it too, not only
  // the whole server's "".
  if (auto* health = server->GetHealthCheckService())
    health->SetServingStatus(isostream::v1::Isostream::service_full_name(), true);
  const std::string host = config.listen.substr(0, config.listen.rfind(':'));
  std::printf("listening on %s:%d\n", host.c_str(), port);
  std::fflush(stdout);
  spdlog::info("isostreamd listening on {}:{} ({}, {} catalogue entries{})", host, port,
               config.tls_cert.empty() ? "plaintext" : "TLS", config.volumes.size(),
               config.token.empty() ? "" : ", bearer token required");

  // The stop signals were blocked before any thread started; wait for one here.
  sigset_t signals = StopSignals();
  int sig = 0;
  sigwait(&signals, &sig);
  spdlog::info("{}: stopping (health NOT_SERVING, finishing frames in flight)",
               sig == SIGINT   ? "SIGINT"
               : sig == SIGHUP ? "SIGHUP"
                               : "SIGTERM");

  if (auto* health = server->GetHealthCheckService()) health->SetServingStatus(false);
  service.BeginShutdown();
  const auto grace = std::chrono::milliseconds(config.shutdown_grace_ms);
  if (!service.WaitForStreams(grace)) spdlog::warn("streams still open after the grace period");
  // Anything still open is cancelled at this deadline.
  server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
  server->Wait();
  // Preparations were told to stop at BeginShutdown, and notice it between steps, slabs and
  // tiles; one inside a step that cannot look (a file being read, OpenVDB decompressing a grid)
  // would hold the exit for as long as that takes, past a service manager's stop timeout.
  // Nothing it holds needs an orderly end (the hierarchy cache is written to a temporary file
  // renamed into place, and a dead writer's temporary file is removed later), so it is left.
  if (const int unfinished = service.WaitForPreparations(std::chrono::seconds(1))) {
    spdlog::info("stopped, leaving {} volume preparation(s) in a step that cannot stop",
                 unfinished);
    // Not spdlog::shutdown(): the thread left behind may log when its step returns, through
    // the default logger that shutdown would release.
    spdlog::default_logger()->flush();
    std::fflush(stdout);
    std::_Exit(0);
  }
  spdlog::info("stopped");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  isostream::KeepFreedMemoryForReuse();  // frames reuse freed memory instead of new pages
  // Block the stop signals in every thread (all threads are created after this), so that one
  // sigwait sees them and no gRPC or TBB thread is interrupted.
  const sigset_t signals = StopSignals();
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  signal(SIGPIPE, SIG_IGN);
  google::protobuf::SetLogHandler(&ProtobufLog);
  gpr_set_log_function(&GrpcLog);

  CLI::App app{
      "isostreamd: streams view-ordered transparent isosurfaces over gRPC.\n"
      "Listens on 127.0.0.1:7878 by default (loopback only); --listen 0.0.0.0:PORT with "
      "--tls-cert/--tls-key to serve a network. Prints 'listening on HOST:PORT' when ready."};
  DaemonConfig defaults;
  std::string config_file, listen, cache_dir, tls_cert, tls_key, token, log_level;
  std::vector<std::string> volumes;
  int threads = 0, max_sessions = 0, max_isovalues = 0, max_dim = 0, chunk_triangles = 0;
  int64_t max_triangles = 0, deadline_ms = 0, idle_timeout_s = 0, cache_max_mb = 0, retain_mb = 0;
  bool no_cache = false;
  app.add_option("--config", config_file, "JSON config file (flags override it)");
  auto* o_listen = app.add_option("--listen", listen,
                                  "HOST:PORT to listen on (default 127.0.0.1:7878; port 0 picks "
                                  "a free port and prints it)");
  auto* o_volume = app.add_option("--volume", volumes,
                                  "catalogue entry NAME=SPEC (repeatable); without any, built-in "
                                  "generators are served under their spec names");
  auto* o_threads = app.add_option("--threads", threads, "worker threads (0: all cores)");
  auto* o_sessions =
      app.add_option("--max-sessions", max_sessions,
                     "concurrent Session/Extract streams and volume-info calls (default 16)");
  auto* o_tris =
      app.add_option("--max-triangles", max_triangles, "triangles per frame (default 4000000)");
  auto* o_iso =
      app.add_option("--max-isovalues", max_isovalues, "isovalues per request (default 16)");
  auto* o_deadline = app.add_option("--deadline-ms", deadline_ms,
                                    "time limit per frame's extraction (default 30000); a "
                                    "client that takes no data for this long is cut off");
  auto* o_idle = app.add_option("--idle-timeout-s", idle_timeout_s,
                                "end a Session with no request and no frame in flight for this "
                                "many seconds (default 300; 0: never)");
  auto* o_cache = app.add_option("--cache-dir", cache_dir, "hierarchy cache directory");
  auto* o_nocache = app.add_flag("--no-cache", no_cache, "never read or write the cache");
  bool no_preload = false;
  auto* o_nopreload = app.add_flag("--no-preload", no_preload,
                                   "prepare catalogue volumes on first use, not at start");
  auto* o_cache_max = app.add_option("--cache-max-mb", cache_max_mb,
                                     "cache size cap; least recently used entries go (default "
                                     "16384)");
  auto* o_cert = app.add_option("--tls-cert", tls_cert, "PEM certificate chain (enables TLS)");
  auto* o_key = app.add_option("--tls-key", tls_key, "PEM private key");
  auto* o_token =
      app.add_option("--token", token, "require 'authorization: Bearer TOKEN' on every call");
  auto* o_dim = app.add_option("--max-dim", max_dim,
                               "largest generator size served without a catalogue (default 257)");
  int64_t generator_mb = 0;
  auto* o_generator_mb = app.add_option("--generator-mb", generator_mb,
                                        "memory for the generated volumes held at once; least "
                                        "recently used idle ones go (default 8192)");
  auto* o_chunk =
      app.add_option("--chunk-triangles", chunk_triangles, "triangles per chunk (default 65536)");
  auto* o_retain = app.add_option("--retain-mb", retain_mb,
                                  "memory for streams' last frames, re-ordered for new views of "
                                  "the same mesh instead of extracted (default 1024; 0: off)");
  auto* o_log =
      app.add_option("--log-level", log_level, "trace|debug|info|warn|error|critical|off");
  // Counts may be written with an exponent ("--max-triangles 1e6"), as the config file and the
  // clients' options take them.
  for (CLI::Option* count : {o_threads, o_sessions, o_tris, o_iso, o_deadline, o_idle, o_cache_max,
                             o_dim, o_generator_mb, o_chunk, o_retain})
    count->transform(isostream::GivenCount());
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Usage errors exit 2, as config errors do; --help 0 if the help could be written.
    if (app.exit(e) != 0) return 2;
    return isostream::FlushStandardOutput("isostreamd") ? 0 : 1;
  }

  spdlog::set_default_logger(spdlog::stderr_color_mt("isostreamd"));
  DaemonConfig config = defaults;
  if (!config_file.empty()) {
    const absl::Status s = isostream::service::LoadConfigFile(config_file, &config);
    if (!s.ok()) {
      std::fprintf(stderr, "isostreamd: %s\n", std::string(s.message()).c_str());
      return 2;
    }
  }
  if (*o_listen) config.listen = listen;
  if (*o_volume) {
    std::set<std::string> seen;  // a flag may replace a config file's entry, not another flag's
    for (const std::string& v : volumes) {
      const size_t eq = v.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == v.size()) {
        std::fprintf(stderr, "isostreamd: --volume wants NAME=SPEC, got '%s'\n", v.c_str());
        return 2;
      }
      if (!seen.insert(v.substr(0, eq)).second) {
        std::fprintf(stderr, "isostreamd: --volume names '%s' twice\n", v.substr(0, eq).c_str());
        return 2;
      }
      config.volumes[v.substr(0, eq)] = v.substr(eq + 1);
    }
  }
  if (*o_threads) config.threads = threads;
  if (*o_sessions) config.limits.max_sessions = max_sessions;
  if (*o_tris) config.limits.max_triangles = max_triangles;
  if (*o_iso) config.limits.max_isovalues = max_isovalues;
  if (*o_deadline) config.limits.deadline_ms = deadline_ms;
  if (*o_idle) config.limits.idle_timeout_s = idle_timeout_s;
  if (*o_cache) config.cache_dir = cache_dir;
  if (*o_nocache) config.no_cache = no_cache;
  if (*o_nopreload) config.preload = !no_preload;
  if (*o_cache_max) config.cache_max_mb = cache_max_mb;
  if (*o_cert) config.tls_cert = tls_cert;
  if (*o_key) config.tls_key = tls_key;
  if (*o_token) {
    // An empty --token (an unset variable, say) would serve without one, silently.
    if (token.empty()) {
      std::fprintf(stderr, "isostreamd: --token is empty; leave it out to serve without a token\n");
      return 2;
    }
    config.token = token;
  }
  if (*o_dim) config.limits.max_dim = max_dim;
  if (*o_generator_mb) config.limits.generator_mb = generator_mb;
  if (*o_chunk) config.chunk_triangles = chunk_triangles;
  if (*o_retain) config.retain_mb = retain_mb;
  if (*o_log) config.log_level = log_level;
  const absl::Status valid = isostream::service::ValidateConfig(config);
  if (!valid.ok()) {
    std::fprintf(stderr, "isostreamd: %s\n", std::string(valid.message()).c_str());
    return 2;
  }
  spdlog::set_level(spdlog::level::from_str(config.log_level));
  // gRPC formats only what reaches its verbosity (errors by default): all of it for a trace.
  if (config.log_level == "trace") gpr_set_log_verbosity(GPR_LOG_SEVERITY_DEBUG);
  return Run(config);
}
