// The extractor's edge -> vertex table: first sight inserts, later lookups find the vertex,
// through growth (rehashing) and after a Reset; Find looks without inserting.
#include "server/extract/edge_vertex_table.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace isostream {
namespace {

TEST(EdgeVertexTable, FindsWhatItInsertedAcrossGrowthAndReset) {
  EdgeVertexTable table(16);  // grows many times below
  std::mt19937_64 rng(3);
  for (int round = 0; round < 3; ++round) {
    std::vector<uint64_t> keys(5000);
    for (auto& k : keys) k = rng() >> 1;  // the extractor's keys leave the top bit clear
    for (size_t i = 0; i < keys.size(); ++i) {
      ASSERT_EQ(table.FindOrInsert(keys[i], uint32_t(i)), EdgeVertexTable::kMissing) << i;
      // Every earlier key is still found with its own value, whenever the table just grew.
      if ((i & (i + 1)) == 0) {
        for (size_t j = 0; j <= i; ++j) ASSERT_EQ(table.FindOrInsert(keys[j], 0xdead), j) << j;
      }
    }
    EXPECT_EQ(table.size(), keys.size());
    for (size_t j = 0; j < keys.size(); ++j) ASSERT_EQ(table.FindOrInsert(keys[j], 7), j);
    // Find reads without inserting: absent keys stay absent.
    for (size_t j = 0; j < keys.size(); ++j) ASSERT_EQ(table.Find(keys[j]), j);
    for (int j = 0; j < 100; ++j) ASSERT_EQ(table.Find(rng() >> 1), EdgeVertexTable::kMissing);
    EXPECT_EQ(table.size(), keys.size());
    table.Reset();
    EXPECT_EQ(table.size(), 0u);
    ASSERT_EQ(table.Find(keys[1]), EdgeVertexTable::kMissing);
    ASSERT_EQ(table.FindOrInsert(keys[0], 9), EdgeVertexTable::kMissing);  // forgotten
    table.Reset();
  }
}

}  // namespace
}  // namespace isostream
