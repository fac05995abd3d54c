#include "server/service/service_core.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <string_view>
#include <vector>

namespace isostream::service {

ServiceCore::ServiceCore(const DaemonConfig& c)
    : config(c),
      retain_budget(c.retain_mb << 20),
      catalogue([&] {
        CatalogueOptions o;
        o.volumes = c.volumes;
        o.max_generator_dim = c.limits.max_dim;
        o.max_generator_bytes = uint64_t(c.limits.generator_mb) << 20;
        o.limits.max_dim = c.volumes.empty() ? c.limits.max_dim : VolumeLimits{}.max_dim;
        if (!c.no_cache) o.cache.dir = c.cache_dir.empty() ? DefaultCacheDir() : c.cache_dir;
        o.cache.max_bytes = uint64_t(c.cache_max_mb) << 20;
        o.build_threads = c.threads;
        if (const char* ms = std::getenv("ISOSTREAMD_TEST_PREPARE_DELAY_MS"))
          o.prepare_delay = std::chrono::milliseconds(std::atoll(ms));
        if (const char* ms = std::getenv("ISOSTREAMD_TEST_PREPARE_STUCK_MS"))
          o.prepare_stuck = std::chrono::milliseconds(std::atoll(ms));
        if (const char* ms = std::getenv("ISOSTREAMD_TEST_RETRY_FAILED_MS"))
          o.retry_failed_after = std::chrono::milliseconds(std::atoll(ms));
        return o;
      }()),
      encoders(std::make_unique<WorkerPool>(
          c.threads > 0 ? c.threads : int(std::max(1u, std::thread::hardware_concurrency())))),
      // One thread per admissible stream: a frame job blocks while its client reads slowly,
      // and must not hold up other streams' frames.
      frames(std::make_unique<WorkerPool>(c.limits.max_sessions + 1)),
      producer(
          [&] {
            FrameSettings f;
            f.chunk_triangles = c.chunk_triangles;
            f.first_chunk_triangles = FirstChunkTriangles(c);
            f.max_queued_chunks = c.max_queued_chunks;
            f.coarse_triangles = c.coarse_triangles;
            f.max_triangles = c.limits.max_triangles;
            f.deadline_ms = c.limits.deadline_ms;
            return f;
          }(),
          encoders.get(), &counters) {}

bool ServiceCore::Authorized(const grpc::CallbackServerContext* ctx) const {
  if (config.token.empty()) return true;
  // Any of the call's authorization headers may carry it; the scheme's name is case-insensitive
  // (RFC 7235: "bearer TOKEN" was refused).
  const auto [first, end] = ctx->client_metadata().equal_range("authorization");
  bool matched = false;
  for (auto it = first; it != end; ++it) {
    const std::string_view given(it->second.data(), it->second.size());
    constexpr std::string_view kScheme = "bearer ";
    if (given.size() < kScheme.size() ||
        !std::equal(kScheme.begin(), kScheme.end(), given.begin(), [](char a, char b) {
          return a == std::tolower(static_cast<unsigned char>(b));
        }))
      continue;
    std::string_view token = given.substr(kScheme.size());
    while (!token.empty() && token.front() == ' ') token.remove_prefix(1);  // 1*SP
    // Constant time in the token's content, so timing does not reveal a matching prefix.
    unsigned diff = token.size() != config.token.size();
    for (size_t i = 0; i < std::min(token.size(), config.token.size()); ++i)
      diff |= unsigned(token[i] ^ config.token[i]);
    matched |= diff == 0;
  }
  return matched;
}

absl::Status ServiceCore::Admit() {
  if (shutting_down.load()) return absl::UnavailableError("the server is shutting down");
  int64_t open = counters.sessions_open.load();
  do {
    if (open >= config.limits.max_sessions) {
      counters.sessions_rejected.fetch_add(1);
      return absl::ResourceExhaustedError("the server has its maximum of " +
                                          std::to_string(config.limits.max_sessions) +
                                          " sessions open; try again later");
    }
  } while (!counters.sessions_open.compare_exchange_weak(open, open + 1));
  counters.sessions_total.fetch_add(1);
  return absl::OkStatus();
}

void ServiceCore::StartIdleReaper() {
  const std::chrono::milliseconds idle = std::chrono::seconds(config.limits.idle_timeout_s);
  // A write the client has not taken for a whole frame deadline will not be: the frame that
  // made it has failed by then (it waits that long for room in the stream at most).
  const std::chrono::milliseconds stall(config.limits.deadline_ms);
  // A stream ends at most a tenth of its timeout (or a second) after it became idle enough.
  const auto shortest = idle.count() > 0 ? std::min(idle, stall) : stall;
  const auto period = std::clamp<std::chrono::milliseconds>(
      shortest / 10, std::chrono::milliseconds(50), std::chrono::milliseconds(1000));
  idle_reaper = std::thread([this, idle, stall, period] {
    std::unique_lock<std::mutex> lock(reaper_mu);
    while (!reaper_cv.wait_for(lock, period, [&] { return reaper_stop; })) {
      std::vector<std::shared_ptr<StreamBase>> open;
      {
        std::lock_guard<std::mutex> streams_lock(streams_mu);
        for (auto& [ptr, weak] : streams)
          if (auto s = weak.lock()) open.push_back(std::move(s));
      }
      const Clock::time_point now = Clock::now();
      for (auto& s : open) s->Reap(now, idle, stall);
    }
  });
}

void ServiceCore::StartPreload() {
  if (!config.preload || config.volumes.empty()) return;
  preloader = std::thread([this] {
    const auto t0 = Clock::now();
    int prepared = 0;
    for (const std::string& name : catalogue.Names()) {
      if (shutting_down.load()) return;
      if (catalogue.Get(name).ok()) ++prepared;  // failures are logged by the catalogue
    }
    spdlog::info("preloaded {} of {} catalogue volumes in {:.1f} s", prepared,
                 config.volumes.size(), std::chrono::duration<double>(Clock::now() - t0).count());
  });
}

void ServiceCore::JoinPreload() {
  if (preloader.joinable()) preloader.join();
}

void ServiceCore::StopIdleReaper() {
  {
    std::lock_guard<std::mutex> lock(reaper_mu);
    reaper_stop = true;
  }
  reaper_cv.notify_all();
  if (idle_reaper.joinable()) idle_reaper.join();
}

}  // namespace isostream::service
