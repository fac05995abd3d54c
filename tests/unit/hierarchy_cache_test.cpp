// The hierarchy cache: hits return the same eta; stale, corrupt, truncated and foreign files
// are detected and rebuilt; an unwritable directory costs only the cache.
#include "server/hierarchy/hierarchy_cache.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "address_space_cap.h"

namespace isostream {
namespace {

namespace fs = std::filesystem;

PaddedSamples Samples(int k, float phase) {
  PaddedSamples s;
  s.k = k;
  s.n = (1 << k) + 1;
  s.data_dims = {s.n, s.n, s.n};
  s.values.resize(size_t(s.n) * s.n * s.n);
  for (size_t i = 0; i < s.values.size(); ++i) s.values[i] = std::sin(0.37f * i + phase);
  return s;
}

class HierarchyCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) /
           ("isostream-cache-" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "-" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    cache_.dir = dir_.string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  HierarchyPtr Get(PaddedSamples s, CacheOutcome* outcome) {
    auto h = LoadOrBuildHierarchy(std::move(s), cache_, {}, outcome);
    EXPECT_TRUE(h.ok()) << h.status();
    return *h;
  }

  // With entries for samples 0 (held by the caller) and 1 (released), 0 the older: a cap with
  // room for two and a third entry stored evict 1, not the held 0.
  void ExpectTheHeldEntryOutlivesANewerOne() {
    CacheOutcome outcome;
    Get(Samples(4, 1), &outcome);  // released at once
    const std::string a = HierarchyCachePath(cache_.dir, Samples(4, 0));
    const std::string b = HierarchyCachePath(cache_.dir, Samples(4, 1));
    const auto now = fs::file_time_type::clock::now();
    fs::last_write_time(a, now - std::chrono::seconds(20));  // the oldest, but held
    fs::last_write_time(b, now - std::chrono::seconds(10));
    cache_.max_bytes = 2 * fs::file_size(a) + fs::file_size(a) / 2;  // room for two entries
    Get(Samples(4, 2), &outcome);
    EXPECT_TRUE(fs::exists(a));
    EXPECT_FALSE(fs::exists(b));
  }

  fs::path dir_;
  HierarchyCacheOptions cache_;
};

TEST_F(HierarchyCacheTest, MissThenHitWithIdenticalEta) {
  CacheOutcome first, second;
  const HierarchyPtr a = Get(Samples(4, 0), &first);
  const HierarchyPtr b = Get(Samples(4, 0), &second);
  EXPECT_EQ(first, CacheOutcome::kMissBuilt);
  EXPECT_EQ(second, CacheOutcome::kHit);
  ASSERT_EQ(a->point_count(), b->point_count());
  EXPECT_EQ(a->LinearEta(), b->LinearEta());
  EXPECT_EQ(a->LinearSamples(), b->LinearSamples());
}

// The file keeps the stored bfloat16 codes (2 bytes per point, plus a small header), and a hit
// returns exactly the codes that were built.
TEST_F(HierarchyCacheTest, FileHoldsTheStoredCodes) {
  CacheOutcome outcome;
  const HierarchyPtr a = Get(Samples(5, 0), &outcome);
  const std::string path = HierarchyCachePath(cache_.dir, Samples(5, 0));
  const uintmax_t payload = uintmax_t(a->point_count()) * sizeof(uint16_t);
  EXPECT_GE(fs::file_size(path), payload);
  EXPECT_LT(fs::file_size(path), payload + 256);
  const HierarchyPtr b = Get(Samples(5, 0), &outcome);
  EXPECT_EQ(outcome, CacheOutcome::kHit);
  EXPECT_EQ(a->LinearEtaCodes(), b->LinearEtaCodes());
}

// With a cap, a store removes the least recently used entries (a hit counts as a use) until
// the entries fit; the new entry and files that are not entries stay.
TEST_F(HierarchyCacheTest, CapEvictsTheLeastRecentlyUsed) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  const std::string a = HierarchyCachePath(cache_.dir, Samples(4, 0));
  const std::string b = HierarchyCachePath(cache_.dir, Samples(4, 1));
  const std::string c = HierarchyCachePath(cache_.dir, Samples(4, 2));
  cache_.max_bytes = 2 * fs::file_size(a) + fs::file_size(a) / 2;  // room for two entries
  Get(Samples(4, 1), &outcome);
  EXPECT_EQ(outcome, CacheOutcome::kMissBuilt);
  const auto now = fs::file_time_type::clock::now();
  fs::last_write_time(a, now - std::chrono::seconds(20));
  fs::last_write_time(b, now - std::chrono::seconds(10));
  std::ofstream(dir_ / "notes.txt") << "not an entry";
  Get(Samples(4, 0), &outcome);  // a is used again: b is now the least recently used
  EXPECT_EQ(outcome, CacheOutcome::kHit);
  Get(Samples(4, 2), &outcome);
  EXPECT_EQ(outcome, CacheOutcome::kMissBuilt);
  EXPECT_TRUE(fs::exists(a));
  EXPECT_FALSE(fs::exists(b));
  EXPECT_TRUE(fs::exists(c));
  EXPECT_TRUE(fs::exists(dir_ / "notes.txt"));
  cache_.max_bytes = 1;  // smaller than any entry: only the newest stays
  Get(Samples(4, 1), &outcome);
  EXPECT_FALSE(fs::exists(a));
  EXPECT_TRUE(fs::exists(b));
  EXPECT_FALSE(fs::exists(c));
  // Trimming applies the cap without a store; a half-written entry whose writer died goes, one
  // whose writer lives (process 1, which always does) stays, and one named with this process's
  // id that it is not writing goes: an earlier process with the same id left it (a container's
  // daemon is always PID 1, and its quick exit leaves a preparation's write unfinished).
  const std::string entry = fs::path(b).filename().string();
  const fs::path dead = dir_ / (entry + ".tmp.999999999.0");
  const fs::path live = dir_ / (entry + ".tmp.1.0");
  const fs::path earlier_self = dir_ / (entry + ".tmp." + std::to_string(::getpid()) + ".7");
  for (const fs::path& p : {dead, live, earlier_self}) std::ofstream(p) << "half";
  cache_.max_bytes = 1;
  TrimHierarchyCache(cache_);
  EXPECT_FALSE(fs::exists(b));
  EXPECT_FALSE(fs::exists(dead));
  EXPECT_TRUE(fs::exists(live));
  EXPECT_FALSE(fs::exists(earlier_self));
}

// Entries whose hierarchies this process still holds (a daemon serving them from memory) go
// after every other, however old their time: read once at start, a served volume's entry
// looked least recently used and other stores evicted it.
TEST_F(HierarchyCacheTest, EntriesStillHeldAreEvictedLast) {
  CacheOutcome outcome;
  HierarchyPtr held = Get(Samples(4, 0), &outcome);
  ExpectTheHeldEntryOutlivesANewerOne();
  held.reset();  // released: the oldest goes first again
  const std::string a = HierarchyCachePath(cache_.dir, Samples(4, 0));
  fs::last_write_time(a, fs::file_time_type::clock::now() - std::chrono::seconds(20));
  Get(Samples(4, 3), &outcome);
  EXPECT_FALSE(fs::exists(a));
  EXPECT_TRUE(fs::exists(HierarchyCachePath(cache_.dir, Samples(4, 2))));
}

TEST_F(HierarchyCacheTest, ChangedSamplesAreNotServedFromCache) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  const HierarchyPtr b = Get(Samples(4, 1), &outcome);
  EXPECT_NE(outcome, CacheOutcome::kHit);
  auto fresh = BuildHierarchy(Samples(4, 1));
  ASSERT_TRUE(fresh.ok());
  EXPECT_EQ((*fresh)->LinearEta(), b->LinearEta());
}

void Corrupt(const std::string& path, long offset_from_end, bool truncate) {
  if (truncate) {
    fs::resize_file(path, fs::file_size(path) - offset_from_end);
    return;
  }
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekp(-offset_from_end, std::ios::end);
  char c = 0x5a;
  f.write(&c, 1);
}

TEST_F(HierarchyCacheTest, CorruptTruncatedAndForeignFilesAreRebuilt) {
  const std::string path = HierarchyCachePath(cache_.dir, Samples(4, 0));
  auto expect = BuildHierarchy(Samples(4, 0));
  ASSERT_TRUE(expect.ok());
  for (int variant = 0; variant < 4; ++variant) {
    CacheOutcome outcome;
    Get(Samples(4, 0), &outcome);  // make sure a good file exists
    ASSERT_TRUE(fs::exists(path));
    if (variant == 0) Corrupt(path, 17, false);  // payload byte: checksum fails
    if (variant == 1) Corrupt(path, 100, true);  // truncated payload
    if (variant == 2) {                          // another format version
      std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
      f.seekp(8);
      const uint32_t v = kHierarchyCacheVersion + 7;
      f.write(reinterpret_cast<const char*>(&v), 4);
    }
    if (variant == 3) {  // not a cache file at all
      std::ofstream(path, std::ios::trunc) << "hello";
    }
    const HierarchyPtr h = Get(Samples(4, 0), &outcome);
    EXPECT_EQ(outcome, CacheOutcome::kInvalidRebuilt) << "variant " << variant;
    EXPECT_EQ((*expect)->LinearEta(), h->LinearEta()) << "variant " << variant;
    Get(Samples(4, 0), &outcome);
    EXPECT_EQ(outcome, CacheOutcome::kHit) << "replaced file is good again, variant " << variant;
  }
}

// A daemon shutting down stops a preparation that reads a cache entry (1025^3: 2.1 GB), as one
// that builds: CANCELLED, and the entry stays for the next start.
TEST_F(HierarchyCacheTest, StopFlagCancelsAHit) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  ASSERT_EQ(outcome, CacheOutcome::kMissBuilt);
  std::atomic<bool> stop{true};
  HierarchyBuildOptions build;
  build.stop = &stop;
  auto h = LoadOrBuildHierarchy(Samples(4, 0), cache_, build, &outcome);
  EXPECT_EQ(h.status().code(), absl::StatusCode::kCancelled) << h.status();
  Get(Samples(4, 0), &outcome);
  EXPECT_EQ(outcome, CacheOutcome::kHit);
}

// A cache directory whose entries' names cannot even be looked up (a component longer than the
// file system allows: ENAMETOOLONG; EACCES for one the daemon may not search) is no cache: the
// hierarchy is built and served, the reason noted. The look-up used to throw out of the
// preparation and end the daemon (std::terminate on a pool thread).
TEST_F(HierarchyCacheTest, UnsearchableDirectoryStillBuilds) {
  fs::create_directories(dir_);  // so that the look-up reaches the long name
  cache_.dir = (dir_ / std::string(300, 'd')).string();
  CacheOutcome outcome;
  std::string why;
  auto h = LoadOrBuildHierarchy(Samples(3, 0), cache_, {}, &outcome, &why);
  ASSERT_TRUE(h.ok()) << h.status();
  EXPECT_EQ(outcome, CacheOutcome::kMissBuilt);
  EXPECT_NE(why.find("not stored"), std::string::npos) << why;
}

TEST_F(HierarchyCacheTest, UnwritableDirectoryStillBuilds) {
  fs::create_directories(dir_);
  std::ofstream(dir_ / "file") << "x";
  cache_.dir = (dir_ / "file" / "sub").string();  // a path under a regular file
  CacheOutcome outcome;
  std::string why;
  auto h = LoadOrBuildHierarchy(Samples(3, 0), cache_, {}, &outcome, &why);
  ASSERT_TRUE(h.ok());
  EXPECT_NE(why.find("cannot"), std::string::npos) << why;
}

// An entry's name is only where it is looked for: one copied under the name of other samples
// (same k and size) is stale, not a hit serving the other samples' hierarchy.
TEST_F(HierarchyCacheTest, AnEntryUnderAnotherSamplesNameIsRebuilt) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  fs::copy_file(HierarchyCachePath(cache_.dir, Samples(4, 0)),
                HierarchyCachePath(cache_.dir, Samples(4, 1)));
  const HierarchyPtr h = Get(Samples(4, 1), &outcome);
  EXPECT_EQ(outcome, CacheOutcome::kInvalidRebuilt);
  auto fresh = BuildHierarchy(Samples(4, 1));
  ASSERT_TRUE(fresh.ok());
  EXPECT_EQ((*fresh)->LinearEta(), h->LinearEta());
}

// A file whose header is right but for its magic is not an entry.
TEST_F(HierarchyCacheTest, AnEntryWithAnotherMagicIsRebuilt) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  {
    std::fstream f(HierarchyCachePath(cache_.dir, Samples(4, 0)),
                   std::ios::in | std::ios::out | std::ios::binary);
    f.write("X", 1);
  }
  Get(Samples(4, 0), &outcome);
  EXPECT_EQ(outcome, CacheOutcome::kInvalidRebuilt);
}

// The cap is "at most max_bytes": entries totalling exactly the cap all stay.
TEST_F(HierarchyCacheTest, EntriesTotallingExactlyTheCapStay) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  const std::string a = HierarchyCachePath(cache_.dir, Samples(4, 0));
  cache_.max_bytes = 3 * fs::file_size(a);  // entries of one k have one size
  Get(Samples(4, 1), &outcome);
  Get(Samples(4, 2), &outcome);
  EXPECT_TRUE(fs::exists(a));
  EXPECT_TRUE(fs::exists(HierarchyCachePath(cache_.dir, Samples(4, 1))));
  EXPECT_TRUE(fs::exists(HierarchyCachePath(cache_.dir, Samples(4, 2))));
}

// A write in progress (its writer, process 1, lives) counts towards the cap: with room for one
// entry, the entry goes and the write stays.
TEST_F(HierarchyCacheTest, AWriteInProgressCountsTowardsTheCap) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  const std::string a = HierarchyCachePath(cache_.dir, Samples(4, 0));
  const uintmax_t size = fs::file_size(a);
  const fs::path live =
      dir_ /
      (fs::path(HierarchyCachePath(cache_.dir, Samples(4, 1))).filename().string() + ".tmp.1.0");
  std::ofstream(live) << std::string(size, 'w');
  cache_.max_bytes = size + size / 2;
  TrimHierarchyCache(cache_);
  EXPECT_FALSE(fs::exists(a));
  EXPECT_TRUE(fs::exists(live));
}

// Only files named as entries are evicted: another ".eta" file in the directory stays.
TEST_F(HierarchyCacheTest, TrimmingLeavesOtherEtaFilesAlone) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);
  std::ofstream(dir_ / "notes.eta") << "not an entry";
  cache_.max_bytes = 1;
  TrimHierarchyCache(cache_);
  EXPECT_FALSE(fs::exists(HierarchyCachePath(cache_.dir, Samples(4, 0))));
  EXPECT_TRUE(fs::exists(dir_ / "notes.eta"));
}

// A hierarchy read from its entry and still held keeps its entry last in the eviction order,
// as one built and stored does (EntriesStillHeldAreEvictedLast).
TEST_F(HierarchyCacheTest, AnEntryHeldAfterAHitIsEvictedLast) {
  CacheOutcome outcome;
  Get(Samples(4, 0), &outcome);  // built, stored and released at once
  HierarchyPtr held = Get(Samples(4, 0), &outcome);
  ASSERT_EQ(outcome, CacheOutcome::kHit);
  ExpectTheHeldEntryOutlivesANewerOne();
}

// A hit reads the cached codes straight into the store: it needs no more memory than a build
// (the whole linear eta beside the samples and the store was 2.15 GB more at 1025^3). Run in a
// child process whose address space is capped at what it uses plus the 257^3 store (110 MB)
// and 16 MB: the 257^3 codes alone are 34 MB.
void HitUnderAddressSpaceCap(PaddedSamples samples, HierarchyCacheOptions cache) {
  const rlim_t store = rlim_t{33} * 33 * 33 * sizeof(HierarchyBrick);
  testing::CapAddressSpaceAbove(store + (rlim_t{16} << 20));
  CacheOutcome outcome;
  const auto h = LoadOrBuildHierarchy(std::move(samples), cache, {}, &outcome);
  std::_Exit(h.ok() && outcome == CacheOutcome::kHit ? 0 : 1);
}

TEST_F(HierarchyCacheTest, HitNeedsNoMoreMemoryThanTheStore) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  CacheOutcome outcome;
  const HierarchyPtr built = Get(Samples(8, 0), &outcome);
  ASSERT_EQ(built->total_bytes(), 33u * 33 * 33 * sizeof(HierarchyBrick));
  EXPECT_EXIT(HitUnderAddressSpaceCap(Samples(8, 0), cache_), ::testing::ExitedWithCode(0), "");
}

}  // namespace
}  // namespace isostream
