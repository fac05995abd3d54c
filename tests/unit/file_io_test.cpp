// Whole-file writes (shared/file_io.h): a file is replaced whole or left as it was.
#include "shared/file_io.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace isostream {
namespace {

namespace fs = std::filesystem;

class FileIo : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string pattern = ::testing::TempDir() + "/isostream_file_io_XXXXXX";
    ASSERT_NE(mkdtemp(pattern.data()), nullptr);
    dir_ = pattern;
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return dir_ + "/" + name; }
  std::vector<std::string> Names() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename());
    std::sort(names.begin(), names.end());
    return names;
  }
  std::string dir_;
};

// A write cut short (here by a file size limit; a full disk or a quota alike) must leave the
// previous file whole and no partial file beside it: an `extract -o` over last run's mesh used
// to leave a truncated one.
TEST_F(FileIo, AFailedWriteLeavesThePreviousFileAndNoPartOfTheNewOne) {
  const std::string path = Path("mesh.ply");
  ASSERT_TRUE(WriteFileBytes(path, "the previous mesh").ok());
  rlimit saved;
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  const rlimit small = {4096, saved.rlim_max};
  auto* const previous = signal(SIGXFSZ, SIG_IGN);  // a write past the limit fails, EFBIG
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  const absl::Status s = WriteFileBytes(path, std::string(1 << 16, 'x'));
  setrlimit(RLIMIT_FSIZE, &saved);
  signal(SIGXFSZ, previous);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("cannot write " + path), std::string::npos) << s;
  auto kept = ReadFileBytes(path);
  ASSERT_TRUE(kept.ok()) << kept.status();
  EXPECT_EQ(*kept, "the previous mesh");
  EXPECT_EQ(Names(), std::vector<std::string>{"mesh.ply"});
}

// A process killed while it writes (here by SIGXFSZ's default action; Ctrl-C or a kill alike)
// leaves the previous file whole and nothing beside it: `extract -o` interrupted left 60 MB
// .partial files.
TEST_F(FileIo, AProcessKilledWhileWritingLeavesNothingBehind) {
  for (const bool existed : {false, true}) {
    SCOPED_TRACE(existed);
    const std::string path = Path("mesh.ply");
    if (existed) {
      ASSERT_TRUE(WriteFileBytes(path, "the previous mesh").ok());
    }
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      const rlimit small = {4096, RLIM_INFINITY};
      signal(SIGXFSZ, SIG_DFL);
      setrlimit(RLIMIT_FSIZE, &small);
      (void)WriteFileBytes(path, std::string(1 << 16, 'x'));
      _exit(0);  // not reached: the write past the limit kills the process
    }
    int status = 0;
    ASSERT_EQ(waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(status)) << status;
    EXPECT_EQ(WTERMSIG(status), SIGXFSZ);
    if (existed) {
      EXPECT_EQ(*ReadFileBytes(path), "the previous mesh");
      EXPECT_EQ(Names(), std::vector<std::string>{"mesh.ply"});
    } else {
      EXPECT_EQ(Names(), std::vector<std::string>{});
    }
  }
}

TEST_F(FileIo, ReplacesAFileWholeAndKeepsItsMode) {
  const std::string path = Path("frame.png");
  ASSERT_TRUE(WriteFileBytes(path, "one").ok());
  ASSERT_TRUE(WriteFileBytes(path, "two, longer").ok());
  EXPECT_EQ(*ReadFileBytes(path), "two, longer");
  EXPECT_EQ(Names(), std::vector<std::string>{"frame.png"});
  const mode_t mask = umask(0);
  umask(mask);
  struct stat st;
  ASSERT_EQ(stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0666 & ~mask);
  // A file made private stays so.
  ASSERT_EQ(chmod(path.c_str(), 0600), 0);
  ASSERT_TRUE(WriteFileBytes(path, "three").ok());
  ASSERT_EQ(stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
}

// A link stays a link (its target is replaced); a device is written in place, never renamed
// over; a directory or a missing folder is an error naming the path.
TEST_F(FileIo, LinksDevicesAndDirectories) {
  const std::string target = Path("target.glb"), link = Path("link.glb");
  ASSERT_TRUE(WriteFileBytes(target, "old").ok());
  fs::create_symlink(target, link);
  ASSERT_TRUE(WriteFileBytes(link, "new").ok());
  EXPECT_TRUE(fs::is_symlink(link));
  EXPECT_EQ(*ReadFileBytes(target), "new");
  EXPECT_EQ(Names(), (std::vector<std::string>{"link.glb", "target.glb"}));

  // A link to nothing yet makes its target, as fopen does.
  const std::string dangling = Path("dangling.ply"), made = Path("made.ply");
  fs::create_symlink(made, dangling);
  ASSERT_TRUE(WriteFileBytes(dangling, "made").ok());
  EXPECT_TRUE(fs::is_symlink(dangling));
  EXPECT_EQ(*ReadFileBytes(made), "made");
  // A hard link keeps seeing the file's contents: written in place.
  const std::string second = Path("second-name.glb");
  fs::create_hard_link(target, second);
  ASSERT_TRUE(WriteFileBytes(target, "newer").ok());
  EXPECT_EQ(*ReadFileBytes(second), "newer");

  EXPECT_TRUE(WriteFileBytes("/dev/null", "discarded").ok());
  EXPECT_TRUE(fs::is_character_file("/dev/null"));

  const absl::Status into_dir = WriteFileBytes(dir_, "x");
  EXPECT_FALSE(into_dir.ok());
  EXPECT_NE(into_dir.message().find(dir_), std::string::npos) << into_dir;
  const absl::Status no_folder = WriteFileBytes(Path("missing/out.ply"), "x");
  EXPECT_EQ(no_folder.code(), absl::StatusCode::kNotFound) << no_folder;
}

// Where the new file cannot be made or would change more than the contents, the file is
// written in place: a name too long for the partial file's suffix, and (checkable as root,
// who can give a file away) another user's file, which a rename would make ours.
TEST_F(FileIo, WrittenInPlaceWhereReplacingCannotWork) {
  const std::string long_name = Path(std::string(250, 'n') + ".ply");
  ASSERT_TRUE(WriteFileBytes(long_name, "first").ok());
  ASSERT_TRUE(WriteFileBytes(long_name, "second").ok());
  EXPECT_EQ(*ReadFileBytes(long_name), "second");
  if (geteuid() != 0) return;  // only root can give a file to another user
  const std::string theirs = Path("theirs.ply");
  ASSERT_TRUE(WriteFileBytes(theirs, "old").ok());
  ASSERT_EQ(chown(theirs.c_str(), 65534, 65534), 0);
  ASSERT_TRUE(WriteFileBytes(theirs, "new").ok());
  struct stat st;
  ASSERT_EQ(stat(theirs.c_str(), &st), 0);
  EXPECT_EQ(st.st_uid, 65534u);
  EXPECT_EQ(*ReadFileBytes(theirs), "new");
}

// A full disk may show only when the file is closed (the bytes were buffered): /dev/full takes
// every write and fails the flush. That is a failed write, named, not a success.
TEST_F(FileIo, AFailureThatShowsOnlyWhenFlushedIsAFailedWrite) {
  const absl::Status s = WriteFileBytes("/dev/full", "a few bytes");
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  EXPECT_EQ(s.message(), "cannot write /dev/full: No space left on device");
}

TEST_F(FileIo, OutputPathsAreCheckedBeforeTheWork) {
  EXPECT_TRUE(CheckOutputPath(Path("new.ply")).ok());
  EXPECT_TRUE(CheckOutputPath("/dev/null").ok());
  EXPECT_EQ(CheckOutputPath(dir_).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(CheckOutputPath(Path("missing/new.ply")).code(), absl::StatusCode::kNotFound);
  // A folder that cannot be written (root writes into any: checked as another user only).
  fs::create_directory(Path("locked"));
  fs::permissions(Path("locked"), fs::perms::owner_read | fs::perms::owner_exec);
  EXPECT_EQ(CheckOutputPath(Path("locked/new.ply")).code(),
            geteuid() == 0 ? absl::StatusCode::kOk : absl::StatusCode::kPermissionDenied);
  fs::permissions(Path("locked"), fs::perms::owner_all);
}

// A link to a file not made yet is written through (fopen makes its target), so the folder
// that must exist is the target's, not the link's: `-o out.ply` with out.ply a link into a
// folder that is gone passed the check and failed only after the volume was prepared and the
// frame extracted ("cannot create out.ply: No such file or directory", exit 1 after minutes).
TEST_F(FileIo, ALinkToAFileInAMissingFolderIsRefusedBeforeTheWork) {
  fs::create_symlink(Path("missing/target.ply"), Path("link.ply"));
  const absl::Status link = CheckOutputPath(Path("link.ply"));
  EXPECT_EQ(link.code(), absl::StatusCode::kNotFound);
  EXPECT_NE(link.message().find("missing/ (where its link points)"), std::string::npos) << link;
  // A link to a file not made yet in a folder that exists stays fine.
  fs::create_symlink(Path("target.ply"), Path("fine.ply"));
  EXPECT_TRUE(CheckOutputPath(Path("fine.ply")).ok());
  EXPECT_TRUE(WriteFileBytes(Path("fine.ply"), "x").ok());
  // Through a chain of relative links, and a loop of them (which no write could follow).
  fs::create_directory(Path("sub"));
  fs::create_symlink("../missing/deeper.ply", Path("sub/hop.ply"));
  fs::create_symlink("sub/hop.ply", Path("chain.ply"));
  EXPECT_EQ(CheckOutputPath(Path("chain.ply")).code(), absl::StatusCode::kNotFound);
  // A longer chain (five links) is followed to its end too: only a loop is refused as one.
  fs::create_symlink("missing/end.ply", Path("hop5.ply"));
  for (int i = 4; i >= 1; --i)
    fs::create_symlink("hop" + std::to_string(i + 1) + ".ply",
                       Path("hop" + std::to_string(i) + ".ply"));
  const absl::Status long_chain = CheckOutputPath(Path("hop1.ply"));
  EXPECT_EQ(long_chain.code(), absl::StatusCode::kNotFound) << long_chain;
  fs::create_symlink("hop5_fine.ply", Path("hop4_fine.ply"));
  fs::create_symlink("hop4_fine.ply", Path("hop3_fine.ply"));
  fs::create_symlink("hop3_fine.ply", Path("hop2_fine.ply"));
  EXPECT_TRUE(CheckOutputPath(Path("hop2_fine.ply")).ok());
  fs::create_symlink("loop_b.ply", Path("loop_a.ply"));
  fs::create_symlink("loop_a.ply", Path("loop_b.ply"));
  const absl::Status loop = CheckOutputPath(Path("loop_a.ply"));
  EXPECT_EQ(loop.code(), absl::StatusCode::kInvalidArgument) << loop;
  EXPECT_NE(loop.message().find("loop of symbolic links"), std::string::npos) << loop;
}

}  // namespace
}  // namespace isostream
