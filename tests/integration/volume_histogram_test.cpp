// A volume's histogram as GetVolumeInfo answers it: bin edges, and the bin counts kept.
#include "server/service/volume_histogram.h"

#include <gtest/gtest.h>

#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "server/hierarchy/prepared_volume.h"
#include "tests/integration/daemon_process.h"

namespace isostream::service {
namespace {

using testing::ScratchDir;

// A width x 2 x 2 volume of uint8 samples value(x), prepared as the daemon does.
PreparedVolume IntegerRamp(
    const ScratchDir& dir, int width, const std::string& name,
    const std::function<int(int)>& value = [](int x) { return x; }) {
  std::vector<char> bytes;
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < width; ++x) bytes.push_back(char(value(x)));
  const std::string path = dir.path() + "/" + name;
  std::ofstream(path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  auto p = PrepareVolume("raw:" + path + ":" + std::to_string(width) + "x2x2:uint8", VolumeLimits{},
                         HierarchyCacheOptions{}, HierarchyBuildOptions{});
  EXPECT_TRUE(p.ok()) << p.status();
  return std::move(*p);
}

// Bin i covers [min + i w, min + (i + 1) w): a sample on an edge is counted above it, whatever
// the bin count (integer data meet every edge when w divides the range). Dividing before
// multiplying put 29 of 0..100 in bin 28 of 100.
TEST(VolumeHistograms, SamplesOnBinEdgesCountInTheBinAbove) {
  ScratchDir dir;
  const PreparedVolume ramp = IntegerRamp(dir, 101, "ramp.raw");
  const VolumeHistograms histograms;
  for (int bins : {100, 50, 25, 20, 10, 7, 4, 3, 2}) {
    SCOPED_TRACE(bins);
    std::vector<uint64_t> expected(size_t(bins), 0);
    for (int x = 0; x <= 100; ++x) expected[std::min(bins - 1, x * bins / 100)] += 4;
    const auto counts = histograms.Get(*ramp.volume, *ramp.hierarchy, bins, [] { return false; });
    ASSERT_TRUE(counts.has_value());
    EXPECT_EQ(*counts, expected);
  }
  // A constant volume: every sample is the maximum, in the closed last bin.
  const PreparedVolume flat = IntegerRamp(dir, 2, "flat.raw", [](int) { return 7; });
  const auto counts =
      VolumeHistograms().Get(*flat.volume, *flat.hierarchy, 4, [] { return false; });
  ASSERT_TRUE(counts.has_value());
  EXPECT_EQ(*counts, (std::vector<uint64_t>{0, 0, 0, 8}));
}

// Eight bin counts are kept; a ninth replaces the least recently used one only (all were
// dropped, so a client cycling through nine paid a whole pass every call). A kept count is
// answered without a pass, which is what a pass that would be cancelled at once shows.
TEST(VolumeHistograms, KeepsTheRecentlyUsedBinCounts) {
  ScratchDir dir;
  const PreparedVolume ramp = IntegerRamp(dir, 101, "ramp.raw");
  const VolumeHistograms histograms;
  auto get = [&](int bins, bool cancelled) {
    return histograms.Get(*ramp.volume, *ramp.hierarchy, bins, [=] { return cancelled; });
  };
  for (int bins = 2; bins <= 9; ++bins) ASSERT_TRUE(get(bins, false).has_value());
  ASSERT_TRUE(get(2, true).has_value());    // kept, and now the most recently used
  ASSERT_TRUE(get(10, false).has_value());  // replaces 3
  EXPECT_FALSE(get(3, true).has_value());
  for (int bins : {2, 4, 5, 6, 7, 8, 9, 10}) EXPECT_TRUE(get(bins, true).has_value()) << bins;
}

}  // namespace
}  // namespace isostream::service
