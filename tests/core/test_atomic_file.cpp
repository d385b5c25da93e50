#include <gtest/gtest.h>

#include <filesystem>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

std::size_t entries(const fs::path& dir) {
  return static_cast<std::size_t>(std::distance(fs::directory_iterator(dir), fs::directory_iterator{}));
}

TEST(AtomicFile, ReplacesOnlyOnCommit) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "out.txt", "old");
  {
    AtomicFile f(dir / "out.txt");
    f.stream() << "new but unfinished";
    EXPECT_EQ(read_file(dir / "out.txt"), "old");  // not yet visible
  }  // destroyed without commit: the old file stays, no temporary is left behind
  EXPECT_EQ(read_file(dir / "out.txt"), "old");
  EXPECT_EQ(entries(dir), 1u);
  write_file_atomic(dir / "out.txt", "new");
  EXPECT_EQ(read_file(dir / "out.txt"), "new");
  EXPECT_EQ(entries(dir), 1u);
}

TEST(AtomicFile, WriterThatThrowsLeavesNothing) {
  const auto dir = test::scratch_dir();
  EXPECT_THROW(write_file_atomic_with(dir / "a.png", [](const fs::path&) { fail("boom"); }), Error);
  EXPECT_EQ(entries(dir), 0u);
}

TEST(AtomicFile, CreatesParentFoldersAndReportsUnwritable) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "a/b/c.txt", "x");
  EXPECT_EQ(read_file(dir / "a/b/c.txt"), "x");
  write_file_atomic(dir / "file", "x");
  EXPECT_THROW(write_file_atomic(dir / "file/below.txt", "y"), Error);  // parent is a file
  EXPECT_THROW(read_file(dir / "nope.txt"), Error);
  EXPECT_THROW(read_file(dir), Error);
}

}  // namespace
}  // namespace d2gs
