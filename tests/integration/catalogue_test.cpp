// The daemon's volume catalogue without a process: names, generator limits and budgets, and
// preparations (queued, shared, given up).
#include "server/service/catalogue.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "tests/integration/daemon_process.h"

namespace isostream::service {
namespace {

using testing::ScratchDir;

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

}  // namespace
}  // namespace isostream::service
