// The rANS symbol stream under the edge-cache codec: arrays of any distribution round-trip,
// and a stream cut short or asked for more symbols than it holds does not decode.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "shared/internal/symbol_stream.h"

namespace isostream {
namespace {

TEST(SymbolStream, RoundTripsAndRejectsEveryTruncationAndExtension) {
  std::mt19937 rng(31);
  std::geometric_distribution<uint32_t> small(0.3);
  std::uniform_int_distribution<uint32_t> any;
  for (int trial = 0; trial < 40; ++trial) {
    const size_t count = 1 + rng() % 3000;
    std::vector<uint32_t> symbols(count);
    for (uint32_t& v : symbols) {
      switch (trial % 4) {
        case 0: v = small(rng); break;                    // skewed, direct tokens
        case 1: v = any(rng) >> (rng() % 32); break;      // every bit width
        case 2: v = 7; break;                             // a single token
        default: v = rng() % 2 ? small(rng) : any(rng);  // mixed
      }
    }
    std::string stream = "prefix";
    internal::AppendSymbols(symbols.data(), count, &stream);
    std::vector<uint32_t> decoded(count);
    size_t at = 6;
    ASSERT_TRUE(internal::ReadSymbols(stream.data(), stream.size(), &at, count, decoded.data()));
    EXPECT_EQ(at, stream.size());
    EXPECT_EQ(decoded, symbols);
    // Fewer bytes never decode, nor do more symbols than were written.
    for (size_t size = 6; size < stream.size(); size += 1 + size / 16) {
      at = 6;
      EXPECT_FALSE(internal::ReadSymbols(stream.data(), size, &at, count, decoded.data()));
    }
    // (A one-token array carries no information per symbol: any count decodes from it.)
    at = 6;
    std::vector<uint32_t> more(count + 1);
    if (trial % 4 != 2) {
      EXPECT_FALSE(
          internal::ReadSymbols(stream.data(), stream.size(), &at, count + 1, more.data()));
    }
    // Edited bytes must never read out of bounds (checked under sanitizers), and mostly fail.
    for (int edit = 0; edit < 50; ++edit) {
      std::string e = stream;
      e[6 + rng() % (e.size() - 6)] = static_cast<char>(rng());
      at = 6;
      internal::ReadSymbols(e.data(), e.size(), &at, count, decoded.data());
    }
  }
}

}  // namespace
}  // namespace isostream
