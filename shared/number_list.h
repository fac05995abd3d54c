// "x,y,z"-style command-line values and ports, shared by the CLI, the viewer, the client, the
// daemon's settings and the mesh renderer.
#pragma once

#include <string>
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

// The port of a "HOST:PORT" address, as gRPC would read it: InvalidArgument unless it is a
// decimal number in 0..65535 (gRPC takes a larger one modulo 65536, a negative one by its low
// 16 bits, and a missing one as 443). Without `required`, an address whose part after its last
// ':' is not a number at all passes (a bare host, "[::1]").
absl::Status CheckPort(std::string_view address, bool required);

// The shortest text that parses back to exactly v ("0" for -0): what tools print of a value a
// user may paste back, such as the eps a budget search found (printed to 6 digits, that eps
// gave another mesh).
std::string ShortestText(double v);
// The same for a float (an isovalue): "0.1", where its double would print 0.10000000149011612.
std::string ShortestText(float v);

}  // namespace isostream
