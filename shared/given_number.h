// A CLI11 check for number options whose 0 means something ("--eps 0": full resolution): CLI11
// reads an empty value as 0, so `--eps ""` would silently ask for it. Used by the CLI and the
// viewer (header only: both already build with CLI11).
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdlib>
#include <string>

namespace isostream {

inline CLI::Validator GivenNumber() {
  return CLI::Validator(
      [](std::string& text) { return text.empty() ? std::string("a number is needed") : ""; },
      "NUMBER");
}

// The same for counts, which also take a whole number written with an exponent or a point
// ("--budget 1e6", "2.5e5"): rewritten as digits before CLI11 converts it, which refused them.
// Anything else is left for CLI11 to refuse. A transform, not a check: checks see a copy.
inline CLI::Validator GivenCount() {
  return CLI::Validator(
      [](std::string& text) {
        if (text.empty()) return std::string("a number is needed");
        if (text.find_first_of("eE.") == std::string::npos) return std::string();
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        if (end != text.c_str() && *end == '\0' && std::isfinite(v) && v == std::floor(v) &&
            std::abs(v) < 9223372036854775808.0)  // 2^63: every such whole double fits
          text = std::to_string(static_cast<long long>(v));
        return std::string();
      },
      "COUNT");
}

}  // namespace isostream
