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

// Writes `bytes` as the file at `path`, whole or not at all: into a new file beside it, renamed
// over `path` once complete, so a failed write (a full disk, a file size limit) leaves the
// previous file as it was and no partial one. The new file has no name until then where the
// file system allows (O_TMPFILE), so a process killed while writing leaves none either. A symbolic link's target is replaced, the link
// kept, and a replaced file's permissions. Written in place instead: what is not a regular file
// (/dev/null, a FIFO), a link to nothing yet, a file with other hard links or of another
// owner, and a file in a folder where no new file can be made or renamed. A file we may not
// write is refused, as fopen would.
absl::Status WriteFileBytes(const std::string& path, std::string_view bytes);

// Whether WriteFileBytes could write `path`, checked before the work that produces its bytes:
// InvalidArgument for a directory, NotFound for a missing folder, PermissionDenied for a
// folder (and file) that cannot be written. A final write may still fail (a full disk).
absl::Status CheckOutputPath(const std::string& path);

// Flushes standard output (C stdio and iostreams); false, after saying so on standard error as
// `program`, if what the program printed could not all be written (a full disk, /dev/full).
bool FlushStandardOutput(const char* program);

// Returns `status` with "`context`: " in front of its message (OK stays OK), so errors from
// parsers that only see bytes can name the file they came from.
absl::Status PrefixStatus(std::string_view context, const absl::Status& status);

}  // namespace isostream
