#include "server/hierarchy/hierarchy_cache.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <set>
#include <vector>

namespace isostream {
namespace {

// The names of the temporary files this process is writing now. One named with this process's
// id but not among them was left by an earlier process that had the same id (a container's
// daemon is always PID 1), killed mid-write or left by a quick exit.
class TemporariesInProgress {
 public:
  static TemporariesInProgress& Get() {
    static TemporariesInProgress instance;
    return instance;
  }
  void Add(const std::string& name) {
    std::lock_guard<std::mutex> lock(mu_);
    names_.insert(name);
  }
  void Remove(const std::string& name) {
    std::lock_guard<std::mutex> lock(mu_);
    names_.erase(name);
  }
  bool Contains(const std::string& name) const {
    std::lock_guard<std::mutex> lock(mu_);
    return names_.count(name) != 0;
  }

 private:
  mutable std::mutex mu_;
  std::set<std::string> names_;
};

// The entries whose hierarchies this process still holds, by file name: a daemon serving a
// volume from memory reads its entry once, at start, so its time said "least recently used"
// while it was the most used, and other volumes' stores evicted it (a rebuild at the next
// start). They go last.
class HeldEntries {
 public:
  static HeldEntries& Get() {
    static HeldEntries instance;
    return instance;
  }
  void Add(const std::string& name, const HierarchyPtr& hierarchy) {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto it = held_.begin(); it != held_.end();)  // those released meanwhile
      it = it->second.expired() ? held_.erase(it) : std::next(it);
    held_[name] = hierarchy;
  }
  bool Contains(const std::string& name) const {
    std::lock_guard<std::mutex> lock(mu_);
    const auto it = held_.find(name);
    return it != held_.end() && !it->second.expired();
  }

 private:
  mutable std::mutex mu_;
  std::map<std::string, std::weak_ptr<const Hierarchy>> held_;
};

constexpr char kMagic[8] = {'I', 'S', 'O', 'H', 'I', 'E', 'R', '\0'};

// Fixed-size, explicitly laid out header; all fields little-endian on the hosts we build for.
struct Header {
  char magic[8];
  uint32_t version;
  uint32_t k;
  uint32_t n;
  int32_t data_dims[3];
  uint64_t samples_hash;
  uint64_t eta_count;
  uint64_t eta_hash;
};

uint64_t SamplesHash(const PaddedSamples& s) {
  XXH3_state_t* st = XXH3_createState();
  XXH3_64bits_reset(st);
  XXH3_64bits_update(st, &s.k, sizeof(s.k));
  XXH3_64bits_update(st, s.data_dims.data(), sizeof(s.data_dims));
  XXH3_64bits_update(st, s.values.data(), s.values.size() * sizeof(float));
  const uint64_t h = XXH3_64bits_digest(st);
  XXH3_freeState(st);
  return h;
}

// Opens a cache entry and checks its header against the samples: on success `in` is at the
// payload (the eta codes, linear) and `eta_hash` is their checksum; otherwise `why` says why
// the entry cannot be used.
bool OpenCache(const std::string& path, const PaddedSamples& s, uint64_t samples_hash,
               std::ifstream* in, uint64_t* eta_hash, std::string* why) {
  in->open(path, std::ios::binary);
  if (!*in) {
    *why = "no cache entry";
    return false;
  }
  Header h{};
  if (!in->read(reinterpret_cast<char*>(&h), sizeof(h))) {
    *why = "cache header truncated";
    return false;
  }
  const uint64_t count = s.stored_points();
  if (std::memcmp(h.magic, kMagic, sizeof(kMagic)) != 0) {
    *why = "cache file has wrong magic";
    return false;
  }
  if (h.version != kHierarchyCacheVersion) {
    *why = "cache format version " + std::to_string(h.version) + " is not " +
           std::to_string(kHierarchyCacheVersion);
    return false;
  }
  if (h.k != static_cast<uint32_t>(s.k) || h.n != static_cast<uint32_t>(s.n) ||
      h.samples_hash != samples_hash || h.eta_count != count) {
    *why = "cache entry is stale (samples changed)";
    return false;
  }
  *eta_hash = h.eta_hash;
  return true;
}

// The hierarchy from a cache entry's payload, read straight into its store (AssembleHierarchy)
// and checked against `eta_hash` as it goes. Null with `why` set if the payload is short or
// fails its checksum (the caller rebuilds); an error only for what a rebuild would meet too
// (out of memory), or CANCELLED once `stop` (may be null) is set, between slabs.
absl::StatusOr<HierarchyPtr> ReadCache(std::ifstream* in, const PaddedSamples& s, uint64_t eta_hash,
                                       const std::atomic<bool>* stop, std::string* why) {
  std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> hash(XXH3_createState(),
                                                                &XXH3_freeState);
  if (!hash) return absl::ResourceExhaustedError("hierarchy cache: out of memory");
  XXH3_64bits_reset(hash.get());
  const size_t plane = static_cast<size_t>(s.stored(0)) * s.stored(1);
  bool stopped = false;
  auto h = AssembleHierarchy(s, [&](int z_begin, int z_end, uint16_t* codes) {
    if (stop != nullptr && stop->load()) {
      stopped = true;
      return false;
    }
    const size_t bytes = size_t(z_end - z_begin) * plane * sizeof(uint16_t);
    if (!in->read(reinterpret_cast<char*>(codes), std::streamsize(bytes))) return false;
    XXH3_64bits_update(hash.get(), codes, bytes);
    return true;
  });
  if (stopped) return absl::CancelledError("preparation stopped");
  if (!h.ok() && h.status().code() == absl::StatusCode::kDataLoss) {
    *why = "cache payload truncated";
    return HierarchyPtr();
  }
  if (h.ok() && XXH3_64bits_digest(hash.get()) != eta_hash) {
    *why = "cache payload fails its checksum";
    return HierarchyPtr();
  }
  return h;
}

bool WriteCache(const std::string& path, const Hierarchy& hier, uint64_t samples_hash,
                std::string* why) {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(path).parent_path(), ec);
  // A name no other writer uses, in this process (two catalogue names for the same samples
  // prepared at once) or another: writers sharing one file would truncate each other's.
  static std::atomic<unsigned> serial{0};
  const std::string tmp =
      path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(serial.fetch_add(1));
  const std::string tmp_name = std::filesystem::path(tmp).filename().string();
  TemporariesInProgress::Get().Add(tmp_name);
  const auto fail = [&](const std::string& what) {
    *why = what;
    std::filesystem::remove(tmp, ec);
    TemporariesInProgress::Get().Remove(tmp_name);
    return false;
  };
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) return fail("cannot create cache file " + tmp + ": " + std::strerror(errno));
  std::FILE* out = ::fdopen(fd, "wb");
  if (out == nullptr) {
    ::close(fd);
    return fail("cannot write cache file " + tmp + ": " + std::strerror(errno));
  }
  Header h{};
  std::memcpy(h.magic, kMagic, sizeof(kMagic));
  h.version = kHierarchyCacheVersion;
  h.k = static_cast<uint32_t>(hier.k());
  h.n = static_cast<uint32_t>(hier.n());
  for (int a = 0; a < 3; ++a) h.data_dims[a] = hier.data_dims()[a];
  h.samples_hash = samples_hash;
  // The codes in linear order are a copy as large as a quarter of the store (2.1 GB at
  // 1025^3): without room for it the hierarchy is served, only not stored.
  UninitializedVector<uint16_t> eta;
  try {
    eta = hier.StoredEtaCodes();
  } catch (const std::bad_alloc&) {
    std::fclose(out);
    return fail("out of memory for the cache file's copy of the eta codes");
  }
  h.eta_count = eta.size();
  h.eta_hash = XXH3_64bits(eta.data(), eta.size() * sizeof(uint16_t));
  const bool written = std::fwrite(&h, sizeof(h), 1, out) == 1 &&
                       std::fwrite(eta.data(), sizeof(uint16_t), eta.size(), out) == eta.size();
  const int write_errno = errno;
  if (std::fclose(out) != 0 || !written)
    return fail("cannot write cache file " + tmp + ": " +
                std::strerror(written ? errno : write_errno));
  std::filesystem::rename(tmp, path, ec);
  if (ec) return fail("cannot move cache file into place: " + ec.message());
  TemporariesInProgress::Get().Remove(tmp_name);
  return true;
}

// Removes the least recently used entries of `dir` (not `keep`) until they total at most
// max_bytes. Entries are the files this cache writes; anything else in the directory is left
// alone. Failures (a file removed meanwhile by another process) are skipped.
void EvictBeyond(const std::string& dir, uint64_t max_bytes, const std::string& keep) {
  struct Entry {
    bool held;  // by this process (HeldEntries): after every other
    std::filesystem::file_time_type used;
    uint64_t bytes;
    std::filesystem::path path;
  };
  std::vector<Entry> entries;
  uint64_t total = 0;
  std::error_code ec;
  for (const auto& f : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = f.path().filename().string();
    if (name.rfind("hierarchy-v", 0) != 0) continue;
    std::error_code e1, e2;
    const uint64_t bytes = f.file_size(e1);
    const auto used = f.last_write_time(e2);
    if (e1 || e2) continue;
    if (f.path().extension() == ".eta") {
      total += bytes;
      if (f.path() != std::filesystem::path(keep))
        entries.push_back({HeldEntries::Get().Contains(name), used, bytes, f.path()});
      continue;
    }
    // "NAME.eta.tmp.PID.SERIAL": a write in progress counts; one whose writer is gone (killed
    // mid-write, or the daemon's quick exit) would stay forever, and goes.
    const size_t tmp = name.rfind(".eta.tmp.");
    if (tmp == std::string::npos) continue;
    const long pid = std::strtol(name.c_str() + tmp + 9, nullptr, 10);
    const bool writer_gone =
        pid > 0 && ((::kill(pid_t(pid), 0) != 0 && errno == ESRCH) ||
                    (pid == ::getpid() && !TemporariesInProgress::Get().Contains(name)));
    if (writer_gone) {
      std::filesystem::remove(f.path(), e1);
    } else {
      total += bytes;
    }
  }
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    return a.held != b.held ? b.held : a.used < b.used;
  });
  for (const Entry& e : entries) {
    if (total <= max_bytes) break;
    std::error_code e1;
    if (std::filesystem::remove(e.path, e1)) total -= e.bytes;
  }
}

}  // namespace

void TrimHierarchyCache(const HierarchyCacheOptions& cache) {
  if (!cache.dir.empty() && cache.max_bytes > 0) EvictBeyond(cache.dir, cache.max_bytes, "");
}

namespace {

std::string PathFor(const std::string& dir, int k, uint64_t samples_hash) {
  char name[64];
  std::snprintf(name, sizeof(name), "hierarchy-v%u-k%d-%016llx.eta", kHierarchyCacheVersion, k,
                static_cast<unsigned long long>(samples_hash));
  return (std::filesystem::path(dir) / name).string();
}

}  // namespace

const char* CacheOutcomeName(CacheOutcome outcome) {
  switch (outcome) {
    case CacheOutcome::kDisabled:
      return "disabled";
    case CacheOutcome::kHit:
      return "hit";
    case CacheOutcome::kMissBuilt:
      return "miss (built)";
    case CacheOutcome::kInvalidRebuilt:
      return "invalid (rebuilt)";
  }
  return "?";
}

std::string DefaultCacheDir() {
  if (const char* d = std::getenv("ISOSTREAM_CACHE_DIR"); d && *d) return d;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/isostream";
  if (const char* home = std::getenv("HOME"); home && *home)
    return std::string(home) + "/.cache/isostream";
  return "";
}

std::string HierarchyCachePath(const std::string& dir, const PaddedSamples& samples) {
  return PathFor(dir, samples.k, SamplesHash(samples));
}

absl::StatusOr<HierarchyPtr> LoadOrBuildHierarchy(PaddedSamples samples,
                                                  const HierarchyCacheOptions& cache,
                                                  const HierarchyBuildOptions& build,
                                                  CacheOutcome* outcome, std::string* why) {
  std::string reason;
  CacheOutcome result = CacheOutcome::kDisabled;
  if (cache.dir.empty()) {
    if (outcome) *outcome = result;
    return BuildHierarchy(std::move(samples), build);
  }
  const uint64_t hash = SamplesHash(samples);
  const std::string path = PathFor(cache.dir, samples.k, hash);
  std::ifstream in;
  uint64_t eta_hash = 0;
  if (OpenCache(path, samples, hash, &in, &eta_hash, &reason)) {
    ISOSTREAM_ASSIGN_OR_RETURN(HierarchyPtr read,
                               ReadCache(&in, samples, eta_hash, build.stop, &reason));
    if (read) {
      std::error_code ec;  // a hit is a use: the eviction order is by this time
      std::filesystem::last_write_time(path, std::filesystem::file_time_type::clock::now(), ec);
      HeldEntries::Get().Add(std::filesystem::path(path).filename().string(), read);
      if (outcome) *outcome = CacheOutcome::kHit;
      if (why) *why = "loaded " + path;
      return read;
    }
  }
  in.close();
  // Not the throwing exists(): a directory this process may not search (EACCES) or a path too
  // long would throw out of the preparation.
  std::error_code ec;
  result =
      std::filesystem::exists(path, ec) ? CacheOutcome::kInvalidRebuilt : CacheOutcome::kMissBuilt;
  ISOSTREAM_ASSIGN_OR_RETURN(HierarchyPtr built, BuildHierarchy(std::move(samples), build));
  std::string write_why;
  // The outcome says what was read; the note says whether the new entry was stored.
  if (!WriteCache(path, *built, hash, &write_why)) {
    reason += "; not stored: " + write_why;
  } else {
    reason += "; stored " + path;
    HeldEntries::Get().Add(std::filesystem::path(path).filename().string(), built);
    if (cache.max_bytes > 0) EvictBeyond(cache.dir, cache.max_bytes, path);
  }
  if (outcome) *outcome = result;
  if (why) *why = reason;
  return built;
}

}  // namespace isostream
