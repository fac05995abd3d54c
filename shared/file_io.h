// Whole-file reads and writes with status results, for the small file formats in shared/ (PLY,
// GLB). Messages carry the path and the system's reason so a user can act on them.
#pragma once

#include <string>
#include <string_view>

#include "shared/status.h"

namespace isostream {

// Reads the whole file at `path`. NotFound if it does not exist, another errno-derived code
// otherwise.
absl::StatusOr<std::string> ReadFileBytes(const std::string& path);

// Creates or truncates the file at `path` and writes `bytes` to it. On failure the file may be
// left partially written.
absl::Status WriteFileBytes(const std::string& path, std::string_view bytes);

// Returns `status` with "`context`: " in front of its message (OK stays OK), so errors from
// parsers that only see bytes can name the file they came from.
absl::Status PrefixStatus(std::string_view context, const absl::Status& status);

}  // namespace isostream
