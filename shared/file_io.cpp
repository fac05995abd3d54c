#include "shared/file_io.h"

#include <absl/strings/str_cat.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <memory>

namespace isostream {
namespace {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// Writes all of `bytes` to `file` and closes it; false with errno set otherwise.
bool WriteAndClose(std::FILE* file, std::string_view bytes) {
  const bool written = std::fwrite(bytes.data(), 1, bytes.size(), file) == bytes.size();
  const int error = errno;
  // fclose flushes; a full disk may only show up here.
  const bool closed = std::fclose(file) == 0;
  if (!written) errno = error;
  return written && closed;
}

absl::Status WriteInPlace(const std::string& path, std::string_view bytes) {
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (!file) return absl::ErrnoToStatus(errno, absl::StrCat("cannot create ", path));
  if (!WriteAndClose(file, bytes))
    return absl::ErrnoToStatus(errno, absl::StrCat("cannot write ", path));
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::string> ReadFileBytes(const std::string& path) {
  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) return absl::ErrnoToStatus(errno, absl::StrCat("cannot open ", path));
  // A device or a pipe (/dev/zero) could be read until memory runs out.
  struct stat st;
  if (::fstat(::fileno(file.get()), &st) != 0 || !S_ISREG(st.st_mode))
    return absl::InvalidArgumentError(absl::StrCat(path, " is not a regular file"));
  std::string bytes;
  char block[1 << 16];
  size_t got;
  while ((got = std::fread(block, 1, sizeof(block), file.get())) > 0) bytes.append(block, got);
  if (std::ferror(file.get()))
    return absl::ErrnoToStatus(errno, absl::StrCat("cannot read ", path));
  return bytes;
}

absl::Status WriteFileBytes(const std::string& path, std::string_view bytes) {
  struct stat st, link;
  const bool exists = ::stat(path.c_str(), &st) == 0;
  const bool is_link = ::lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode);
  // In place: what is not a regular file, a link to nothing yet (fopen makes its target), and
  // a file a rename would change more than the contents of: its hard links would keep the old
  // contents, and another user's file would become ours.
  if ((exists && (!S_ISREG(st.st_mode) || st.st_nlink > 1 || st.st_uid != ::geteuid())) ||
      (is_link && !exists))
    return WriteInPlace(path, bytes);
  // A file we may not write is not replaced either (the rename would allow it).
  if (exists && ::access(path.c_str(), W_OK) != 0)
    return absl::ErrnoToStatus(errno, absl::StrCat("cannot write ", path));
  const mode_t previous_mode = st.st_mode & 07777;
  std::string target = path;
  if (is_link) {
    char resolved[PATH_MAX];
    if (::realpath(path.c_str(), resolved) == nullptr) return WriteInPlace(path, bytes);
    target = resolved;
  }
  // Beside the target, so the rename stays within one file system; O_EXCL with a name no other
  // writer in this process or another uses. Mode 0666 less the umask, as fopen would create.
  static std::atomic<unsigned> serial{0};
  const std::string partial =
      absl::StrCat(target, ".partial-", ::getpid(), "-", serial.fetch_add(1));
  const int fd = ::open(partial.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) {
    if (errno == EACCES || errno == EROFS || errno == EPERM || errno == ENAMETOOLONG)
      return WriteInPlace(path, bytes);
    return absl::ErrnoToStatus(errno, absl::StrCat("cannot create ", path));
  }
  // A file made private stays private when replaced.
  if (exists) (void)::fchmod(fd, previous_mode);
  std::FILE* file = ::fdopen(fd, "wb");
  if (file == nullptr) {
    const int error = errno;
    ::close(fd);
    ::unlink(partial.c_str());
    return absl::ErrnoToStatus(error, absl::StrCat("cannot write ", path));
  }
  if (!WriteAndClose(file, bytes)) {
    const int error = errno;
    ::unlink(partial.c_str());
    return absl::ErrnoToStatus(error, absl::StrCat("cannot write ", path));
  }
  if (::rename(partial.c_str(), target.c_str()) != 0) {
    // Refused (a sticky folder, say): the write itself worked, so write in place instead.
    ::unlink(partial.c_str());
    return WriteInPlace(path, bytes);
  }
  return absl::OkStatus();
}

absl::Status CheckOutputPath(const std::string& path) {
  struct stat st;
  const bool exists = ::stat(path.c_str(), &st) == 0;
  if (exists && S_ISDIR(st.st_mode))
    return absl::InvalidArgumentError(absl::StrCat(path, " is a directory"));
  if (exists && !S_ISREG(st.st_mode)) return absl::OkStatus();  // a device: written in place
  const size_t slash = path.rfind('/');
  const std::string folder = slash == std::string::npos ? "." : path.substr(0, slash + 1);
  if (::stat(folder.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
    return absl::NotFoundError(absl::StrCat("cannot create ", path, ": no folder ", folder));
  if (exists) {
    if (::access(path.c_str(), W_OK) == 0) return absl::OkStatus();
    return absl::PermissionDeniedError(absl::StrCat("cannot write ", path, ": not writable"));
  }
  if (::access(folder.c_str(), W_OK) == 0) return absl::OkStatus();
  return absl::PermissionDeniedError(absl::StrCat("cannot create ", path, ": ", folder,
                                                  " is not writable"));
}

bool FlushStandardOutput(const char* program) {
  std::cout.flush();
  const bool written = std::fflush(stdout) == 0 && !std::ferror(stdout) && std::cout.good();
  if (!written)
    std::fprintf(stderr, "%s: cannot write standard output: %s\n", program, std::strerror(errno));
  return written;
}

absl::Status PrefixStatus(std::string_view context, const absl::Status& status) {
  if (status.ok()) return status;
  return absl::Status(status.code(), absl::StrCat(absl::string_view(context.data(), context.size()),
                                                  ": ", status.message()));
}

}  // namespace isostream
