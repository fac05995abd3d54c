#include "shared/file_io.h"

#include <absl/strings/str_cat.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <memory>
#include <optional>

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

// Partial files' names: one no other writer in this process or another uses.
std::string PartialName(const std::string& target) {
  static std::atomic<unsigned> serial{0};
  return absl::StrCat(target, ".partial-", ::getpid(), "-", serial.fetch_add(1));
}

// Writes `bytes` into a file without a name in the target's folder (O_TMPFILE), then names it
// `target`: killed before that (Ctrl-C, a kill, a crash, a file size limit), the process leaves
// nothing behind, where a named partial file stayed. nullopt where that cannot be done (a file
// system without unnamed files, no /proc, a name too long): nothing was named then.
std::optional<absl::Status> WriteUnnamedThenName(const std::string& target, const std::string& path,
                                                 std::string_view bytes, bool keep_mode,
                                                 mode_t mode) {
  const size_t slash = target.rfind('/');
  const std::string folder = slash == std::string::npos ? "."
                             : slash == 0               ? "/"
                                                        : target.substr(0, slash);
  const int fd = ::open(folder.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0666);
  if (fd < 0) return std::nullopt;
  const auto failed = [&](int error) {
    ::close(fd);
    return absl::ErrnoToStatus(error, absl::StrCat("cannot write ", path));
  };
  if (keep_mode) (void)::fchmod(fd, mode);  // a file made private stays private when replaced
  for (size_t done = 0; done < bytes.size();) {
    const ssize_t n =
        ::write(fd, bytes.data() + done, std::min<size_t>(bytes.size() - done, 1 << 30));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return failed(n < 0 ? errno : EIO);
    done += size_t(n);
  }
  const std::string self = absl::StrCat("/proc/self/fd/", fd);
  // A new name is made whole at once; an existing file is replaced by a rename, which a link
  // cannot do, from a name beside it that exists only between the two calls.
  if (::linkat(AT_FDCWD, self.c_str(), AT_FDCWD, target.c_str(), AT_SYMLINK_FOLLOW) == 0)
    return ::close(fd) == 0 ? absl::OkStatus() : failed(errno);
  if (errno != EEXIST) {
    ::close(fd);
    return std::nullopt;
  }
  const std::string partial = PartialName(target);
  if (::linkat(AT_FDCWD, self.c_str(), AT_FDCWD, partial.c_str(), AT_SYMLINK_FOLLOW) != 0) {
    ::close(fd);
    return std::nullopt;
  }
  if (::close(fd) != 0) {
    const int error = errno;
    ::unlink(partial.c_str());
    return absl::ErrnoToStatus(error, absl::StrCat("cannot write ", path));
  }
  if (::rename(partial.c_str(), target.c_str()) != 0) {
    ::unlink(partial.c_str());
    return std::nullopt;
  }
  return absl::OkStatus();
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
  if (std::optional<absl::Status> written =
          WriteUnnamedThenName(target, path, bytes, exists, previous_mode))
    return *written;
  // Else a named partial file beside the target, so the rename stays within one file system;
  // O_EXCL. Mode 0666 less the umask, as fopen would create.
  const std::string partial = PartialName(target);
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
  // A link to a file not made yet is written through, making its target: the folder that must
  // exist is the target's.
  std::string made = path;
  if (!exists) {
    int hops = 0;
    while (::lstat(made.c_str(), &st) == 0 && S_ISLNK(st.st_mode)) {
      if (++hops > 40)
        return absl::InvalidArgumentError(
            absl::StrCat("cannot create ", path, ": a loop of symbolic links"));
      char target[4096];
      const ssize_t n = ::readlink(made.c_str(), target, sizeof(target));
      if (n <= 0 || size_t(n) == sizeof(target)) break;
      const std::string to(target, size_t(n));
      const size_t at = made.rfind('/');
      made = to[0] == '/' || at == std::string::npos ? to : made.substr(0, at + 1) + to;
    }
  }
  const size_t slash = made.rfind('/');
  const std::string folder = slash == std::string::npos ? "." : made.substr(0, slash + 1);
  if (::stat(folder.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
    return absl::NotFoundError(absl::StrCat("cannot create ", path, ": no folder ", folder,
                                            made == path ? "" : " (where its link points)"));
  if (exists) {
    if (::access(path.c_str(), W_OK) == 0) return absl::OkStatus();
    return absl::PermissionDeniedError(absl::StrCat("cannot write ", path, ": not writable"));
  }
  if (::access(folder.c_str(), W_OK) == 0) return absl::OkStatus();
  return absl::PermissionDeniedError(
      absl::StrCat("cannot create ", path, ": ", folder, " is not writable"));
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
