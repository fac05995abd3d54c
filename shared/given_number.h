// A CLI11 check for number options whose 0 means something ("--eps 0": full resolution): CLI11
// reads an empty value as 0, so `--eps ""` would silently ask for it. Used by the CLI and the
// viewer (header only: both already build with CLI11).
#pragma once

#include <CLI/CLI.hpp>
#include <cerrno>
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
// A count that is not whole, or past 2^63 - 1, is refused here by name (CLI11 said only "Could
// not convert", and took 99999999999999999999 as the largest count silently). Other text is
// left for CLI11 to refuse. A transform, not a check: checks see a copy.
inline CLI::Validator GivenCount() {
  return CLI::Validator(
      [](std::string& text) {
        if (text.empty()) return std::string("a number is needed");
        char* end = nullptr;
        if (text.find_first_of("eE.") == std::string::npos) {
          errno = 0;
          (void)std::strtoll(text.c_str(), &end, 10);
          if (end != text.c_str() && *end == '\0' && errno == ERANGE)
            return text + " is past the largest count, 2^63 - 1";
          return std::string();
        }
        const double v = std::strtod(text.c_str(), &end);
        if (end == text.c_str() || *end != '\0' || std::isnan(v)) return std::string();
        if (v != std::floor(v)) return text + " is not a whole number";
        if (!(std::abs(v) < 9223372036854775808.0))  // 2^63: every smaller whole double fits
          return text + " is past the largest count, 2^63 - 1";
        text = std::to_string(static_cast<long long>(v));
        return std::string();
      },
      "COUNT");
}

}  // namespace isostream
