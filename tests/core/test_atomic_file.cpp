#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include <csignal>

#include <algorithm>
#include <filesystem>
#include <string>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"
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

// A write the file system refuses part-way (here the process's file size limit, as a full disk would):
// the output keeps what it held, no temporary is left, and the error names the file. Files and encoded
// images alike (OpenCV's own file writers did not report a failed close).
TEST(AtomicFile, AWriteThatFailsPartWayLeavesTheOldFileAndNoTemporary) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "out.bin", "old");
  write_file_atomic(dir / "out.png", "old png");
  Image noise(600, 400, 3);
  for (std::size_t i = 0; i < noise.pixels.size(); ++i) noise.pixels[i] = static_cast<float>((i * 7919) % 251) / 250.0f;
  rlimit saved{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  const auto previous = std::signal(SIGXFSZ, SIG_IGN);  // the write fails with EFBIG instead of a signal
  rlimit small = saved;
  small.rlim_cur = 64 * 1024;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  std::string first, second;
  try {
    write_file_atomic(dir / "out.bin", std::string(1 << 20, 'x'));
  } catch (const Error& e) {
    first = e.what();
  }
  try {
    write_image(dir / "out.png", noise);
  } catch (const Error& e) {
    second = e.what();
  }
  setrlimit(RLIMIT_FSIZE, &saved);
  std::signal(SIGXFSZ, previous);
  EXPECT_EQ(first, (dir / "out.bin").string() + ": write failed (disk full?)");
  EXPECT_EQ(second, (dir / "out.png").string() + ": write failed (disk full?)");
  EXPECT_EQ(read_file(dir / "out.bin"), "old");
  EXPECT_EQ(read_file(dir / "out.png"), "old png");
  EXPECT_EQ(entries(dir), 2u);
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

// Commands check where they will write before they work (check_output_folder / check_output_file).
TEST(AtomicFile, OutputPathsAreCheckedBeforeAnythingIsWritten) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "file", "x");
  const auto message = [](auto&& f) -> std::string {
    try {
      f();
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  // Folders that exist or can be created pass, and nothing is created.
  EXPECT_EQ(message([&] { check_output_folder(dir); }), "");
  EXPECT_EQ(message([&] { check_output_folder(dir / "new/deeper"); }), "");
  EXPECT_EQ(message([&] { check_output_file(dir / "new/out.json"); }), "");
  EXPECT_EQ(message([&] { check_output_file(dir / "file"); }), "");  // overwritten atomically
  EXPECT_FALSE(fs::exists(dir / "new"));
  // A folder that is a file, or a path under a file.
  const std::string is_file = message([&] { check_output_folder(dir / "file"); });
  EXPECT_NE(is_file.find((dir / "file").string() + ": exists and is not a folder"), std::string::npos) << is_file;
  const std::string under = message([&] { check_output_folder(dir / "file/run/deeper"); });
  EXPECT_NE(under.find((dir / "file/run/deeper").string() + ": cannot write here: "), std::string::npos) << under;
  EXPECT_NE(under.find((dir / "file").string() + " is a file, not a folder"), std::string::npos) << under;
  const std::string file_under = message([&] { check_output_file(dir / "file/imr.json"); });
  EXPECT_NE(file_under.find((dir / "file/imr.json").string() + ": cannot write here"), std::string::npos) << file_under;
  const std::string file_is_dir = message([&] { check_output_file(dir); });
  EXPECT_NE(file_is_dir.find("is a folder"), std::string::npos) << file_is_dir;
  EXPECT_NE(message([] { check_output_file(""); }), "");
  EXPECT_EQ(std::count(under.begin(), under.end(), '\n'), 0);
}

// Named pipes and devices are refused before they are opened: opening a pipe blocks until a writer comes
// (every reader of d2gs hung on one), a device may never end.
TEST(AtomicFile, ReadsOnlyRegularFiles) {
  const auto dir = test::scratch_dir();
  ASSERT_EQ(::mkfifo((dir / "pipe").c_str(), 0600), 0);
  const auto message = [](const fs::path& p) {
    try {
      read_file(p);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message(dir / "pipe"), (dir / "pipe").string() + ": is a named pipe, expected a file");
  EXPECT_EQ(message("/dev/null"), "/dev/null: is a device, expected a file");
  EXPECT_EQ(message(dir), dir.string() + ": is a folder, expected a file");
  EXPECT_EQ(message(dir / "none"), (dir / "none").string() + ": file not found");
  fs::create_symlink(dir / "loop_b", dir / "loop_a");
  fs::create_symlink(dir / "loop_a", dir / "loop_b");
  EXPECT_EQ(message(dir / "loop_a").rfind((dir / "loop_a").string() + ": cannot be read: ", 0), 0u) << message(dir / "loop_a");
  // The same as output folders: refused before any work (create_directories failed on them after it).
  EXPECT_THROW(check_output_folder(dir / "loop_a"), Error);
  fs::create_symlink(dir / "nowhere", dir / "dangling");
  try {
    check_output_folder(dir / "dangling");
    ADD_FAILURE() << "a dangling link was taken as a folder to create";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("is a symbolic link to " + (dir / "nowhere").string() + ", which does not exist"),
              std::string::npos)
        << e.what();
  }
  write_file_atomic(dir / "file", "x");
  fs::create_symlink(dir / "file", dir / "link");
  EXPECT_EQ(read_file(dir / "link"), "x");
}

}  // namespace
}  // namespace d2gs
