// A CLI11 check for number options whose 0 means something ("--eps 0": full resolution): CLI11
// reads an empty value as 0, so `--eps ""` would silently ask for it. Used by the CLI and the
// viewer (header only: both already build with CLI11).
#pragma once

#include <CLI/CLI.hpp>
#include <string>

namespace isostream {

inline CLI::Validator GivenNumber() {
  return CLI::Validator(
      [](std::string& text) { return text.empty() ? std::string("a number is needed") : ""; },
      "NUMBER");
}

}  // namespace isostream
