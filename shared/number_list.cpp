#include "shared/number_list.h"

#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

namespace isostream {

absl::StatusOr<std::vector<double>> ParseNumberList(std::string_view text, std::string_view what) {
  std::vector<double> out;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t end = std::min(text.find(',', start), text.size());
    // Spaces around an item are allowed on both sides (strtod alone took them before only).
    std::string_view field = text.substr(start, end - start);
    while (!field.empty() && std::isspace(static_cast<unsigned char>(field.front())))
      field.remove_prefix(1);
    while (!field.empty() && std::isspace(static_cast<unsigned char>(field.back())))
      field.remove_suffix(1);
    const std::string item(field);
    char* stop = nullptr;
    const double v = std::strtod(item.c_str(), &stop);
    if (item.empty() || stop != item.c_str() + item.size() || std::isnan(v))
      return absl::InvalidArgumentError(std::string(what) + ": '" + item + "' is not a number");
    if (!std::isfinite(v))  // "inf", or past the double range (1e309)
      return absl::InvalidArgumentError(std::string(what) + ": '" + item +
                                        "' is not a finite number");
    out.push_back(v);
    start = end + 1;
  }
  return out;
}

absl::Status ParseImageSize(std::string_view text, std::string_view what, int max_side, int* width,
                            int* height) {
  const auto bad = [&] {
    return absl::InvalidArgumentError(std::string(what) + ": '" + std::string(text) +
                                      "' is not WxH with sides in 1.." + std::to_string(max_side));
  };
  const size_t x = text.find('x');
  if (x == std::string_view::npos) return bad();
  int64_t side[2];
  const std::string_view parts[2] = {text.substr(0, x), text.substr(x + 1)};
  for (int i = 0; i < 2; ++i) {
    const char* end = parts[i].data() + parts[i].size();
    const auto [at, ec] = std::from_chars(parts[i].data(), end, side[i]);
    if (parts[i].empty() || ec != std::errc() || at != end || side[i] < 1 || side[i] > max_side)
      return bad();
  }
  *width = int(side[0]);
  *height = int(side[1]);
  return absl::OkStatus();
}

absl::Status CheckPort(std::string_view address, bool required) {
  const size_t colon = address.rfind(':');
  const std::string_view port = colon == std::string_view::npos ? "" : address.substr(colon + 1);
  const std::string_view digits = !port.empty() && port[0] == '-' ? port.substr(1) : port;
  const bool numeric =
      !digits.empty() && digits.find_first_not_of("0123456789") == std::string_view::npos;
  if (!numeric && !required) return absl::OkStatus();
  int value = 0;
  const bool fits =
      numeric && port[0] != '-' && digits.size() <= 5 &&
      std::from_chars(digits.data(), digits.data() + digits.size(), value).ec == std::errc() &&
      value <= 65535;
  if (fits && colon != 0) return absl::OkStatus();
  return absl::InvalidArgumentError("'" + std::string(address) +
                                    "' is not HOST:PORT with a port in 0..65535");
}

namespace {

template <typename T>
std::string Shortest(T v) {
  char text[32];
  const auto result = std::to_chars(text, text + sizeof(text), v == 0 ? T(0) : v);
  return std::string(text, result.ptr);
}

}  // namespace

std::string ShortestText(double v) { return Shortest(v); }
std::string ShortestText(float v) { return Shortest(v); }

}  // namespace isostream
