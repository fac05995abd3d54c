#include "shared/internal/symbol_stream.h"

#include <algorithm>
#include <cstring>
#include <vector>

#include "shared/internal/varint.h"
#include "shared/uninitialized_vector.h"

namespace isostream::internal {
namespace {

constexpr int kProbabilityBits = 12;
constexpr uint32_t kTotal = uint32_t{1} << kProbabilityBits;
constexpr uint32_t kDirectTokens = 128;
// Direct tokens, then 4 per bit width from 8 to 32.
constexpr uint32_t kMaxTokens = kDirectTokens + 4 * 25;
// rANS state interval [kLow, 256 kLow): renormalizing by bytes keeps the state below 2^31.
constexpr uint32_t kLow = uint32_t{1} << 23;
// Interleaved rANS states.
constexpr size_t kStates = 4;
static_assert(kStates == 4, "AppendSymbols' unrolled loop pushes four states");

// Number of bits needed to write v (0 for 0).
uint32_t BitWidth(uint32_t v) { return v == 0 ? 0 : 32 - static_cast<uint32_t>(__builtin_clz(v)); }

struct Token {
  uint32_t token;
  uint32_t extra_bits;  // how many
  uint32_t extra;       // their value
};

Token Tokenize(uint32_t v) {
  if (v < kDirectTokens) return {v, 0, 0};
  const uint32_t width = BitWidth(v);  // 8..32
  const uint32_t bits = width - 3;
  return {kDirectTokens + 4 * (width - 8) + ((v >> bits) & 3), bits,
          v & ((uint32_t{1} << bits) - 1)};
}

// Token counts scaled to frequencies summing to kTotal, every token that occurs getting at
// least 1.
void Normalize(const uint32_t* counts, uint32_t alphabet, size_t total, uint32_t* freq) {
  int64_t sum = 0;
  uint32_t largest = 0;
  for (uint32_t t = 0; t < alphabet; ++t) {
    freq[t] = 0;
    if (counts[t] == 0) continue;
    const uint64_t scaled = (uint64_t{counts[t]} * kTotal + total / 2) / total;
    freq[t] = std::max<uint32_t>(1, static_cast<uint32_t>(scaled));
    sum += freq[t];
    if (counts[t] > counts[largest]) largest = t;
  }
  // Rounding leaves sum within about one per token of kTotal: settle the difference on the
  // largest frequencies, which it changes least in proportion.
  freq[largest] += static_cast<uint32_t>(std::max<int64_t>(kTotal - sum, 0));
  sum = std::max<int64_t>(sum, kTotal);
  while (sum > kTotal) {
    uint32_t top = 0;
    for (uint32_t t = 1; t < alphabet; ++t) top = freq[t] > freq[top] ? t : top;
    --freq[top];
    --sum;
  }
}

// Exact x / freq for x < 2^31 by one multiply: m = floor(2^(31+s) / freq) + 1 with 2^s >= freq
// (Granlund and Montgomery's round-up method; m <= 2^32, so x * m < 2^63).
struct EncodeSymbol {
  uint64_t multiplier;
  uint32_t shift;
  uint32_t freq;
  uint32_t start;
  uint32_t renorm_limit;  // the state must be below this before the symbol is pushed
};

// Writes into a buffer sized beforehand for the worst case (29 bits a value), four bytes at a
// time, so the hot loop has no capacity checks.
class BitWriter {
 public:
  explicit BitWriter(uint8_t* out) : p_(out) {}
  void Put(uint32_t value, uint32_t bits) {  // bits <= 29
    acc_ |= uint64_t{value} << count_;
    count_ += bits;
    if (count_ >= 32) {
      const uint32_t word = static_cast<uint32_t>(acc_);
      std::memcpy(p_, &word, 4);  // little-endian host (frame_codec.cpp asserts it)
      p_ += 4;
      acc_ >>= 32;
      count_ -= 32;
    }
  }
  // Writes the bits still held, the last byte zero-padded; returns the end of the data.
  uint8_t* Finish() {
    for (; count_ > 0; count_ = count_ > 8 ? count_ - 8 : 0) {
      *p_++ = static_cast<uint8_t>(acc_);
      acc_ >>= 8;
    }
    return p_;
  }

 private:
  uint8_t* p_;
  uint64_t acc_ = 0;
  uint32_t count_ = 0;
};

class BitReader {
 public:
  BitReader(const uint8_t* data, size_t size) : p_(data), end_(data + size) {}
  // False if the stream holds fewer than `bits` (<= 29) more bits.
  bool Get(uint32_t bits, uint32_t* value) {
    while (count_ < bits) {
      if (p_ == end_) return false;
      acc_ |= uint64_t{*p_++} << count_;
      count_ += 8;
    }
    *value = static_cast<uint32_t>(acc_ & ((uint64_t{1} << bits) - 1));
    acc_ >>= bits;
    count_ -= bits;
    return true;
  }
  // True when every byte was read and the padding bits are zero.
  bool AtEnd() const { return p_ == end_ && count_ < 8 && acc_ == 0; }

 private:
  const uint8_t* p_;
  const uint8_t* end_;
  uint64_t acc_ = 0;
  uint32_t count_ = 0;
};

}  // namespace

void AppendSymbols(const uint32_t* symbols, size_t count, std::string* out) {
  UninitializedVector<uint8_t> tokens(count);
  UninitializedVector<uint8_t> extra(4 * count + 8);
  BitWriter extra_bits(extra.data());
  // Four histograms: a run of one token would otherwise wait on its own count's last update.
  uint32_t counts[4][kMaxTokens] = {};
  uint32_t largest_token = 0;
  for (size_t i = 0; i < count; ++i) {
    const Token t = Tokenize(symbols[i]);
    tokens[i] = static_cast<uint8_t>(t.token);
    ++counts[i & 3][t.token];
    largest_token = std::max(largest_token, t.token);
    if (t.extra_bits) extra_bits.Put(t.extra, t.extra_bits);
  }
  const size_t extra_size = static_cast<size_t>(extra_bits.Finish() - extra.data());
  const uint32_t alphabet = largest_token + 1;
  for (uint32_t t = 0; t < alphabet; ++t)
    counts[0][t] += counts[1][t] + counts[2][t] + counts[3][t];

  uint32_t freq[kMaxTokens] = {};
  Normalize(counts[0], alphabet, count, freq);
  PutVarint32(alphabet, out);
  EncodeSymbol table[kMaxTokens];
  uint32_t start = 0;
  for (uint32_t t = 0; t < alphabet; ++t) {
    PutVarint32(freq[t], out);
    EncodeSymbol& e = table[t];
    e.freq = freq[t];
    e.start = start;
    start += freq[t];
    if (e.freq == 0) continue;
    const uint32_t s = BitWidth(e.freq - 1);  // 2^s >= freq
    e.shift = 31 + s;
    e.multiplier = ((uint64_t{1} << e.shift) / e.freq) + 1;
    e.renorm_limit = ((kLow >> kProbabilityBits) << 8) * e.freq;
  }

  // rANS codes last symbol first, so the stream is written back to front. The states take
  // turns (symbol i goes to state i % kStates), so consecutive pushes do not wait on each
  // other's multiplies. A symbol emits at most two bytes (the state is below 2^31 and shrinks
  // below 2^19 freq before the push).
  UninitializedVector<uint8_t> stream(2 * count + 4 * kStates);
  uint8_t* end = stream.data() + stream.size();
  uint8_t* p = end;
  uint32_t x[kStates] = {kLow, kLow, kLow, kLow};
  auto push = [&p, &table](uint32_t& state, uint8_t token) {
    const EncodeSymbol& e = table[token];
    // Zero, one or two bytes, without branches: whether a byte goes out depends on the data
    // and would be mispredicted about every other symbol. The byte below p is always written
    // (the bytes kept for the final states leave room) and kept only if p moves.
    for (int byte = 0; byte < 2; ++byte) {
      const uint32_t emit = state >= e.renorm_limit;
      p[-1] = static_cast<uint8_t>(state);
      p -= emit;
      state >>= 8 * emit;
    }
    const uint32_t q = static_cast<uint32_t>((state * e.multiplier) >> e.shift);
    state = (q << kProbabilityBits) + (state - q * e.freq) + e.start;
  };
  size_t i = count;
  while (i % kStates != 0) {
    --i;
    push(x[i % kStates], tokens[i]);
  }
  while (i > 0) {  // unrolled so that the states stay in registers
    i -= kStates;
    push(x[3], tokens[i + 3]);
    push(x[2], tokens[i + 2]);
    push(x[1], tokens[i + 1]);
    push(x[0], tokens[i]);
  }
  p -= 4 * kStates;
  std::memcpy(p, x, 4 * kStates);  // little-endian host
  PutVarint32(static_cast<uint32_t>(end - p), out);
  out->append(reinterpret_cast<const char*>(p), static_cast<size_t>(end - p));
  PutVarint32(static_cast<uint32_t>(extra_size), out);
  out->append(reinterpret_cast<const char*>(extra.data()), extra_size);
}

bool ReadSymbols(const char* data, size_t size, size_t* at, size_t count, uint32_t* symbols) {
  const auto* bytes = reinterpret_cast<const uint8_t*>(data);
  uint32_t alphabet = 0;
  if (!GetVarint32(bytes, size, at, &alphabet) || alphabet == 0 || alphabet > kMaxTokens) {
    return false;
  }
  uint32_t freq[kMaxTokens], start[kMaxTokens];
  uint32_t sum = 0;
  for (uint32_t t = 0; t < alphabet; ++t) {
    if (!GetVarint32(bytes, size, at, &freq[t]) || freq[t] > kTotal) return false;
    start[t] = sum;
    sum += freq[t];
    if (sum > kTotal) return false;
  }
  if (sum != kTotal) return false;
  uint8_t slot_token[kTotal];
  for (uint32_t t = 0; t < alphabet; ++t) {
    std::memset(slot_token + start[t], static_cast<int>(t), freq[t]);
  }

  uint32_t rans_size = 0, extra_size = 0;
  if (!GetVarint32(bytes, size, at, &rans_size) || rans_size < 4 * kStates ||
      rans_size > size - *at) {
    return false;
  }
  const uint8_t* p = bytes + *at;
  const uint8_t* rans_end = p + rans_size;
  *at += rans_size;
  if (!GetVarint32(bytes, size, at, &extra_size) || extra_size > size - *at) return false;
  BitReader extra_bits(bytes + *at, extra_size);
  *at += extra_size;

  uint32_t x[kStates];
  std::memcpy(x, p, 4 * kStates);
  p += 4 * kStates;
  for (uint32_t state : x) {
    if (state < kLow || state >= (kLow << 8)) return false;
  }
  for (size_t i = 0; i < count; ++i) {
    uint32_t& state = x[i % kStates];
    const uint32_t slot = state & (kTotal - 1);
    const uint32_t t = slot_token[slot];
    state = freq[t] * (state >> kProbabilityBits) + slot - start[t];
    while (state < kLow) {
      if (p == rans_end) return false;
      state = (state << 8) | *p++;
    }
    if (t < kDirectTokens) {
      symbols[i] = t;
    } else {
      const uint32_t width = (t - kDirectTokens) / 4 + 8;
      const uint32_t bits = width - 3;
      uint32_t low;
      if (!extra_bits.Get(bits, &low)) return false;
      symbols[i] = ((4 + ((t - kDirectTokens) & 3)) << bits) | low;
    }
  }
  for (uint32_t state : x) {
    if (state != kLow) return false;
  }
  return p == rans_end && extra_bits.AtEnd();
}

}  // namespace isostream::internal
