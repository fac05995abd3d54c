#include "shared/number_list.h"

#include <cmath>
#include <cstdlib>
#include <string>

namespace isostream {

absl::StatusOr<std::vector<double>> ParseNumberList(std::string_view text, std::string_view what) {
  std::vector<double> out;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t end = std::min(text.find(',', start), text.size());
    const std::string item(text.substr(start, end - start));
    char* stop = nullptr;
    const double v = std::strtod(item.c_str(), &stop);
    if (item.empty() || stop != item.c_str() + item.size() || !std::isfinite(v))
      return absl::InvalidArgumentError(std::string(what) + ": '" + item + "' is not a number");
    out.push_back(v);
    start = end + 1;
  }
  return out;
}

}  // namespace isostream
