#include "server/service/catalogue.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <thread>

#include "server/volume/generators.h"
#include "server/volume/padding.h"
#include "server/volume/stored_planes.h"
#include "shared/frame_notes.h"
#include "shared/malloc_tuning.h"

namespace isostream::service {
namespace {

// A client's volume name as error messages quote it: shortened, so a long name cannot push
// the status past gRPC's metadata limit (the client would see RESOURCE_EXHAUSTED instead).
std::string Quoted(const std::string& name) {
  constexpr size_t kShown = 100;
  if (name.size() <= kShown) return "'" + name + "'";
  return "'" + name.substr(0, kShown) + "...' (" + std::to_string(name.size()) + " bytes)";
}

// Decimal digits only, at most `max_digits` of them (so that they parse without overflow), and
// no leading zero: one number, one spelling, so "sphere:065" cannot be prepared and held as a
// volume of its own beside "sphere:65".
bool AllDigits(const std::string& s, size_t max_digits = 9) {
  return !s.empty() && s.size() <= max_digits && (s[0] != '0' || s.size() == 1) &&
         std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
}

// "kind:N" or "noise:N:SEED" with a known generator and 2 <= N <= max_dim. Anything else (a
// path, raw:..., a huge N) is refused, so a client cannot reach the filesystem or make the
// daemon allocate a large volume.
// Also gives the volume's one name: noise:N:1 is noise:N (seed 1 is the default), as leading
// zeros are refused, so that one volume is prepared, held and counted once.
absl::Status CheckGeneratorSpec(const std::string& spec, int max_dim,
                                std::string* canonical = nullptr) {
  const size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  static const char* const kKinds[] = {"cayley", "buckyball", "sphere", "shells", "noise"};
  const bool known = std::find_if(std::begin(kKinds), std::end(kKinds),
                                  [&](const char* k) { return kind == k; }) != std::end(kKinds);
  if (!known || colon == std::string::npos)
    return absl::NotFoundError("unknown volume " + Quoted(spec) +
                               ": this daemon has no catalogue and serves the generators "
                               "cayley:N, buckyball:N, sphere:N, shells:N, noise:N[:SEED]");
  std::string rest = spec.substr(colon + 1);
  const size_t seed_colon = rest.find(':');
  if (seed_colon != std::string::npos) {
    if (kind != "noise") return absl::NotFoundError("unknown volume " + Quoted(spec));
    const std::string seed = rest.substr(seed_colon + 1);
    if (!AllDigits(seed, 10) || std::stoull(seed) > 0xffffffffull)
      return absl::NotFoundError("unknown volume " + Quoted(spec) +
                                 ": a noise SEED is an integer in [0, 2^32)");
    rest = rest.substr(0, seed_colon);
    if (canonical && std::stoull(seed) == kNoiseDefaultSeed) *canonical = kind + ":" + rest;
  }
  if (!AllDigits(rest)) return absl::NotFoundError("unknown volume " + Quoted(spec));
  const long n = std::stol(rest);
  if (n < 2 || n > max_dim)
    return absl::NotFoundError("unknown volume " + Quoted(spec) +
                               ": generators are served with 2.." + std::to_string(max_dim) +
                               " samples per axis (the daemon's --max-dim)");
  return absl::OkStatus();
}

// The planes per axis a generator spec Check has accepted stores: its whole cube's, or, for a
// side a little past a power of two, its own and stand-ins for the rest of the padding
// (stored_planes.h: sphere:514 keeps 538 of its 1025^3 cube's planes per axis).
uint64_t GeneratorStoredPlanes(const std::string& spec) {
  const int n = std::stoi(spec.substr(spec.find(':') + 1));  // stops at a noise seed's ':'
  const int k = HierarchyLevelFor({n, n, n});
  const auto axes = StandInPlanes(k, {n, n, n});
  return axes ? (*axes)[0].planes.size() : (uint64_t{1} << k) + 1;
}

// What a generator volume's hierarchy store will take: nearly all a prepared volume holds,
// known before preparing it.
uint64_t GeneratorStoreBytes(const std::string& spec) {
  const uint64_t bricks =
      (GeneratorStoredPlanes(spec) + HierarchyBrick::kMask) >> HierarchyBrick::kLog2;
  return bricks * bricks * bricks * sizeof(HierarchyBrick);
}

// What a generator volume's preparation holds beside the store while it runs: its padded
// samples (the stored planes' floats), and half as much again for the generated grid and what
// the build allocates (measured peaks over the store: 548 MB at 513^3 = 1.01 x the cube's 540 MB,
// and 90 MB at 257^3 = 1.32 x; BENCHMARKS.md).
uint64_t GeneratorSampleBytes(const std::string& spec) {
  const uint64_t planes = GeneratorStoredPlanes(spec);
  return 6 * planes * planes * planes;
}

absl::Status ShuttingDown() {
  return absl::UnavailableError(
      "the server is shutting down (the volume was still being prepared); try again when it is "
      "back");
}

std::string MiB(uint64_t bytes) { return std::to_string((bytes + (1 << 20) - 1) >> 20) + " MiB"; }

}  // namespace

VolumeCatalogue::VolumeCatalogue(CatalogueOptions options) : options_(std::move(options)) {
  TrimHierarchyCache(options_.cache);  // the cap holds from the start, not from the first store
}

VolumeCatalogue::~VolumeCatalogue() { Stop(); }

void VolumeCatalogue::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_.store(true);
  }
  prepared_cv_.notify_all();
}

int VolumeCatalogue::WaitForPreparations(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  prepared_cv_.wait_for(lock, timeout, [&] { return preparations_running_ == 0; });
  return preparations_running_;
}

absl::Status VolumeCatalogue::Check(const std::string& name, std::string* canonical) const {
  if (name.empty()) return absl::InvalidArgumentError("no volume named");
  if (options_.volumes.empty())
    return CheckGeneratorSpec(name, options_.max_generator_dim, canonical);
  if (!options_.volumes.count(name)) {
    // The names a client may ask for (ListVolumes gives them too): a user who typed the
    // generator spec the catalogue entry was made from, or another case, sees what to ask for.
    constexpr size_t kNamed = 10;
    std::string known;
    size_t named = 0;
    for (const auto& [entry, spec] : options_.volumes) {
      if (named == kNamed) break;
      known += (named++ == 0 ? "" : ", ") + Quoted(entry);
    }
    if (options_.volumes.size() > kNamed)
      known += " and " + std::to_string(options_.volumes.size() - kNamed) + " more";
    return absl::NotFoundError("unknown volume " + Quoted(name) + "; the catalogue has " + known +
                               " (`isostream volumes` lists them)");
  }
  return absl::OkStatus();
}

absl::StatusOr<ServedVolumePtr> VolumeCatalogue::Get(const std::string& requested,
                                                     const std::function<bool()>& cancelled) {
  std::string name = requested;
  ISOSTREAM_RETURN_IF_ERROR(Check(requested, &name));
  std::unique_lock<std::mutex> lock(mu_);
  if (stop_.load()) {
    auto it = entries_.find(name);
    if (it != entries_.end() && it->second->served) return it->second->served;
    return ShuttingDown();
  }
  std::shared_ptr<Entry> entry;
  {
    auto& e = entries_[name];
    const bool added = !e;
    if (added) {
      e = std::make_shared<Entry>();
      if (options_.volumes.empty()) e->store_bytes = GeneratorStoreBytes(name);
    }
    e->last_use = ++use_clock_;
    entry = e;
    if (options_.volumes.empty()) {
      // A volume already held or being prepared has its memory: only a new one can be refused.
      const absl::Status room = MakeRoomLocked(name);
      if (!room.ok() && added) {
        entries_.erase(name);
        return room;
      }
    }
  }
  if (entry->served) return entry->served;
  if (!entry->preparing) {
    if (!entry->failed.ok() &&
        std::chrono::steady_clock::now() - entry->failed_at < options_.retry_failed_after)
      return entry->failed;
    entry->preparing = true;
    entry->started = false;
    entry->failed = absl::OkStatus();
    EnqueueLocked(name, entry);
  }
  ++entry->waiters;
  absl::StatusOr<ServedVolumePtr> outcome = ShuttingDown();
  for (;;) {
    if (entry->served) {
      outcome = entry->served;
      break;
    }
    if (!entry->preparing) {
      outcome = entry->failed;
      break;
    }
    if (stop_.load()) break;
    if (cancelled && cancelled()) {
      outcome = absl::CancelledError("gave up waiting for the volume");
      break;
    }
    prepared_cv_.wait_for(lock, kCancelPoll);
  }
  if (--entry->waiters == 0 && entry->preparing && !entry->started && !stop_.load())
    AbandonLocked(name, entry);
  return outcome;
}

void VolumeCatalogue::EnqueueLocked(const std::string& name, const std::shared_ptr<Entry>& entry) {
  line_.emplace_back(name, entry);
  if (line_runners_ == kPreparationThreads) return;
  ++line_runners_;
  preparations_.Submit([this] { RunLine(); });
}

void VolumeCatalogue::RunLine() {
  for (;;) {
    std::pair<std::string, std::shared_ptr<Entry>> next;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (line_.empty()) {
        --line_runners_;
        return;
      }
      next = std::move(line_.front());
      line_.pop_front();
    }
    Prepare(next.first, next.second);
  }
}

void VolumeCatalogue::AbandonLocked(const std::string& name, const std::shared_ptr<Entry>& entry) {
  spdlog::info("preparing volume '{}' dropped before it started: nobody waits for it", name);
  entry->abandoned = true;
  entry->preparing = false;
  const auto in_line = std::find_if(line_.begin(), line_.end(),
                                    [&](const auto& item) { return item.second == entry; });
  if (in_line != line_.end()) line_.erase(in_line);
  EraseIfCurrentLocked(name, entry);
  prepared_cv_.notify_all();  // a job at the memory gate gives up
}

void VolumeCatalogue::EraseIfCurrentLocked(const std::string& name,
                                           const std::shared_ptr<Entry>& entry) {
  auto it = entries_.find(name);
  if (it != entries_.end() && it->second == entry) entries_.erase(it);
}

void VolumeCatalogue::Prepare(const std::string& name, const std::shared_ptr<Entry>& entry) {
  const bool generated = options_.volumes.empty();
  const std::string spec = generated ? name : options_.volumes.at(name);
  // Catalogue volumes are outside the generators' budget: they pass the gate in order only.
  const uint64_t sample_bytes = generated ? GeneratorSampleBytes(name) : 0;
  const bool started = StartPreparation(name, entry, sample_bytes);
  if (!started) {
    std::lock_guard<std::mutex> lock(mu_);
    if (entry->abandoned) return;  // its entry is gone; otherwise stopped, as below
  }
  // The test hook stands for a slow preparation, so Stop cuts it short too.
  const auto delay_end = std::chrono::steady_clock::now() + options_.prepare_delay;
  while (!stop_.load() && std::chrono::steady_clock::now() < delay_end)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  if (started) std::this_thread::sleep_for(options_.prepare_stuck);
  HierarchyBuildOptions build;
  build.threads = options_.build_threads;
  build.stop = &stop_;
  absl::StatusOr<PreparedVolume> prepared = absl::CancelledError("preparation stopped");
  if (started && !stop_.load())
    prepared = PrepareVolume(spec, options_.limits, options_.cache, build);
  const bool stopped = !prepared.ok() && stop_.load();
  ServedVolumePtr served;
  absl::Status failed;
  if (stopped) {
    // Given up for the shutdown, not failed: nothing to log as an error or to remember.
    ReturnFreedMemory();
    spdlog::info("preparing volume '{}' stopped: shutting down", name);
    failed = ShuttingDown();
  } else if (!prepared.ok()) {
    // A preparation that failed part way freed what it had made: the grid's leaves are heap
    // blocks, which the untrimmed heap (malloc_tuning.h) kept (after padding 'sphere:1025'
    // ran out of memory the daemon stayed at 4.7 GB).
    ReturnFreedMemory();
    spdlog::error("preparing volume '{}' ({}) failed: {}", name, spec,
                  std::string(prepared.status().message()));
    // A catalogue entry's message names the spec, which the operator wrote: it stays in the
    // log and is not shown to clients. Nor is its code: the client's request was right
    // (INVALID_ARGUMENT made the viewer call it an argument error).
    failed = generated ? prepared.status()
                       : absl::FailedPreconditionError("volume " + Quoted(name) +
                                                       " could not be prepared on the daemon "
                                                       "(see its log)");
  } else {
    auto volume = std::make_shared<ServedVolume>();
    volume->name = name;
    volume->prepared = std::move(*prepared);
    QuantizationFor(*volume->prepared.volume, &volume->box, &volume->position_bits);
    volume->position_error = PositionErrorBound(volume->box, volume->position_bits);
    // What the volume holds, and of which planes (stand-ins for the rest: stored_planes.h).
    const Hierarchy& hierarchy = *volume->prepared.hierarchy;
    const std::array<int, 3>& stored = hierarchy.stored_dims();
    const std::string planes = hierarchy.stored_point_count() < hierarchy.point_count()
                                   ? std::to_string(stored[0]) + "x" + std::to_string(stored[1]) +
                                         "x" + std::to_string(stored[2]) + " of the " +
                                         std::to_string(hierarchy.n()) + "^3 cube's planes"
                                   : "the whole " + std::to_string(hierarchy.n()) + "^3 cube";
    spdlog::info(
        "prepared volume '{}': {}x{}x{} in {:.0f} ms (hierarchy cache: {}), {} position bits, "
        "store {} ({})",
        name, volume->prepared.volume->dims[0], volume->prepared.volume->dims[1],
        volume->prepared.volume->dims[2],
        1e3 * (volume->prepared.load_s + volume->prepared.pad_s + volume->prepared.hierarchy_s),
        CacheOutcomeName(volume->prepared.cache), volume->position_bits,
        MiB(hierarchy.total_bytes()), planes);
    // A cache the daemon cannot write to rebuilds every hierarchy at every start: say so.
    const std::string& note = volume->prepared.cache_note;
    if (note.find("not stored") != std::string::npos)
      spdlog::warn("volume '{}': hierarchy cache: {}", name, note);
    const std::string coarse = CoarseValuesNote(volume->prepared.volume->min_value,
                                                volume->prepared.volume->max_value, name);
    if (!coarse.empty()) spdlog::warn("volume {}", coarse);
    prepared_.fetch_add(1);
    ReturnFreedMemory();  // what preparing freed (the volume's grid above all) is not reused
    served = std::move(volume);
  }
  std::lock_guard<std::mutex> lock(mu_);
  if (started) EndPreparationLocked(sample_bytes);
  entry->preparing = false;
  if (served) {
    entry->served = std::move(served);
  } else {
    entry->failed = failed;
    if (stopped || generated) {
      // Nothing is held: a generated volume's bytes must not keep others out.
      EraseIfCurrentLocked(name, entry);
    } else {
      entry->failed_at = std::chrono::steady_clock::now();  // a slow failure gets its wait too
    }
  }
  prepared_cv_.notify_all();
}

bool VolumeCatalogue::StartPreparation(const std::string& name, const std::shared_ptr<Entry>& entry,
                                       uint64_t sample_bytes) {
  std::unique_lock<std::mutex> lock(mu_);
  const uint64_t budget = options_.max_generator_bytes;
  // In arrival order: a volume that fits only when fewer run must not be passed for good by
  // smaller ones that keep fitting beside the others.
  gate_.push_back(entry.get());
  bool said = false, start = false;
  for (;;) {
    if (entry->abandoned || stop_.load()) break;
    // No volume is dropped for samples: they are gone in a minute, and the volume that would
    // go first is often the one just prepared, its frame still being drawn.
    if (gate_.front() == entry.get() &&
        (preparations_running_ == 0 ||
         HeldBytesLocked() + preparation_bytes_ + sample_bytes <= budget)) {
      start = true;
      break;
    }
    if (!said && sample_bytes > 0) {  // (a catalogue volume waits only for its turn)
      spdlog::info(
          "preparing volume '{}' waits for memory: {} of volumes held or being built, {} of "
          "samples in preparations running, {} more needed, {} for generated volumes{}",
          name, MiB(HeldBytesLocked()), MiB(preparation_bytes_), MiB(sample_bytes), MiB(budget),
          gate_.front() == entry.get() ? "" : ", behind others waiting");
      said = true;
    }
    prepared_cv_.wait(lock);  // a preparation started or ended, one was dropped, or Stop
  }
  gate_.erase(std::find(gate_.begin(), gate_.end(), entry.get()));
  prepared_cv_.notify_all();  // the next in line may go now
  if (!start) return false;
  ++preparations_running_;
  preparation_bytes_ += sample_bytes;
  entry->started = true;
  spdlog::info("preparing volume '{}'", name);
  return true;
}

void VolumeCatalogue::EndPreparationLocked(uint64_t sample_bytes) {
  --preparations_running_;
  preparation_bytes_ -= sample_bytes;
  prepared_cv_.notify_all();
}

uint64_t VolumeCatalogue::HeldBytesLocked() const {
  uint64_t bytes = 0;
  for (const auto& [name, entry] : entries_) bytes += entry->store_bytes;
  return bytes;
}

absl::Status VolumeCatalogue::MakeRoomLocked(const std::string& keep) {
  const uint64_t budget = options_.max_generator_bytes;
  const uint64_t needed = entries_.at(keep)->store_bytes;
  if (needed > budget)  // refused before anything is dropped for it
    return absl::ResourceExhaustedError(
        "volume " + Quoted(keep) + " needs " + MiB(needed) + ", more than the " + MiB(budget) +
        " this daemon keeps for generated volumes: ask for a smaller one");
  const size_t max_count = size_t(std::max(1, options_.max_generator_volumes));
  while (entries_.size() > max_count || HeldBytesLocked() > budget) {
    // Entries being prepared are skipped: dropping one would let a second request start a
    // second build of the same volume, beside the uncounted first.
    auto oldest = entries_.end();
    for (auto it = entries_.begin(); it != entries_.end(); ++it) {
      if (it->first == keep || !it->second->served) continue;
      if (oldest != entries_.end() && it->second->last_use >= oldest->second->last_use) continue;
      oldest = it;
    }
    if (oldest == entries_.end()) break;
    spdlog::info("dropping volume '{}' (least recently used of {} generator volumes, {} held)",
                 oldest->first, entries_.size(), MiB(HeldBytesLocked()));
    // A build or frames in progress hold their own references; the memory goes when they end.
    entries_.erase(oldest);
  }
  const uint64_t held = HeldBytesLocked();
  if (held <= budget) return absl::OkStatus();  // over the count at most, until a build ends
  const std::string others = MiB(held - needed) + " of the " + MiB(budget);
  return absl::ResourceExhaustedError("volume " + Quoted(keep) + " needs " + MiB(needed) +
                                      ", and generated volumes being prepared hold " + others +
                                      " this daemon keeps for them: try again when they are ready");
}

size_t VolumeCatalogue::queued_preparations() const {
  std::lock_guard<std::mutex> lock(mu_);
  return line_.size() + preparations_.queued();
}

int VolumeCatalogue::held_count() const {
  std::lock_guard<std::mutex> lock(mu_);
  return int(entries_.size());
}

std::vector<std::string> VolumeCatalogue::Names() const {
  std::vector<std::string> names;
  for (const auto& [name, spec] : options_.volumes) names.push_back(name);
  return names;
}

}  // namespace isostream::service
