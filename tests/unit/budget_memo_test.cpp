// The budget memo (server/extract/budget_memo.h): what it finds, and which entry goes when it
// is full.
#include "server/extract/budget_memo.h"

#include <gtest/gtest.h>

#include <vector>

namespace isostream {
namespace {

TEST(BudgetMemo, FindsByIsovalueSetAndBudget) {
  BudgetMemo memo;
  EXPECT_FALSE(memo.Find({0.5f}, 1000).has_value());
  memo.Store({0.5f, 0.2f}, 1000, 0.25);
  EXPECT_EQ(memo.Find({0.2f, 0.5f}, 1000), 0.25);  // the same set in another order
  EXPECT_EQ(memo.Find({0.5f, 0.2f}, 1000), 0.25);
  EXPECT_FALSE(memo.Find({0.2f, 0.5f}, 999).has_value());
  EXPECT_FALSE(memo.Find({0.5f}, 1000).has_value());
  memo.Store({0.2f, 0.5f}, 1000, 0.5);  // a new search's answer replaces the old
  EXPECT_EQ(memo.Find({0.5f, 0.2f}, 1000), 0.5);
  // Another isovalue set at the same budget is an entry of its own: it replaces nothing.
  memo.Store({0.5f}, 1000, 0.75);
  EXPECT_EQ(memo.Find({0.5f}, 1000), 0.75);
  EXPECT_EQ(memo.Find({0.2f, 0.5f}, 1000), 0.5);
}

// Full, it forgets the entry stored or refreshed longest ago, not the newest; storing an entry
// again refreshes it and takes no second place.
TEST(BudgetMemo, ForgetsTheOldestEntryWhenFull) {
  constexpr int kCapacity = 64;
  BudgetMemo memo;
  for (int i = 0; i < kCapacity; ++i) memo.Store({0.5f}, 100 + i, 0.001 * i);
  for (int i = 0; i < kCapacity; ++i) EXPECT_EQ(memo.Find({0.5f}, 100 + i), 0.001 * i) << i;
  // Entries stored again many times hold one place each.
  for (int round = 0; round < 3 * kCapacity; ++round) memo.Store({0.5f}, 100 + kCapacity - 1, 7.0);
  for (int i = 0; i < kCapacity - 1; ++i) EXPECT_TRUE(memo.Find({0.5f}, 100 + i).has_value()) << i;
  memo.Store({0.5f}, 100, 1.0);  // the oldest, refreshed: now the newest
  memo.Store({0.5f}, 1, 2.0);    // one more: the oldest now (budget 101) goes
  EXPECT_EQ(memo.Find({0.5f}, 1), 2.0);
  EXPECT_EQ(memo.Find({0.5f}, 100), 1.0);
  EXPECT_FALSE(memo.Find({0.5f}, 101).has_value());
  for (int i = 2; i < kCapacity; ++i) EXPECT_TRUE(memo.Find({0.5f}, 100 + i).has_value()) << i;
  EXPECT_EQ(memo.Find({0.5f}, 100 + kCapacity - 1), 7.0);
}

}  // namespace
}  // namespace isostream
