// "x,y,z"-style command-line values, shared by the CLI, the viewer and the mesh renderer.
#pragma once

#include <string_view>
#include <vector>

#include "shared/status.h"

namespace isostream {

// Parses comma-separated finite numbers. InvalidArgument naming `what` and the bad item
// ("--iso: 'abc' is not a number") for an empty item, trailing junk, NaN or Inf.
absl::StatusOr<std::vector<double>> ParseNumberList(std::string_view text, std::string_view what);

// "WxH" with 1 <= W, H <= max_side. InvalidArgument naming `what` otherwise (numbers that
// overflow an int included: they are refused, not wrapped).
absl::Status ParseImageSize(std::string_view text, std::string_view what, int max_side, int* width,
                            int* height);

}  // namespace isostream
