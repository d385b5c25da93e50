// CRC-32 against zlib's values, the folder lock (flock) and the removal of temporaries left by killed
// writers.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <string>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/checksum.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

TEST(Crc32, MatchesZlib) {
  // Values from Python's zlib.crc32.
  EXPECT_EQ(crc32("123456789"), 0xCBF43926u);  // the standard check value
  EXPECT_EQ(crc32(""), 0u);
  EXPECT_EQ(crc32("a"), 0xE8B7BE43u);
  std::string bytes(1000, '\0');
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>((i * 7 + 3) % 251);
  EXPECT_EQ(crc32(bytes), 0xA2F92763u);  // zlib.crc32(bytes((i*7+3)%251 for i in range(1000)))
  // In pieces of every alignment, as one.
  for (std::size_t cut : {1u, 3u, 8u, 13u, 999u})
    EXPECT_EQ(crc32(std::string_view(bytes).substr(cut), crc32(std::string_view(bytes).substr(0, cut))), 0xA2F92763u);
  // Every single-bit change is seen.
  for (std::size_t i = 0; i < bytes.size(); i += 37) {
    std::string b = bytes;
    b[i] = static_cast<char>(b[i] ^ (1 << (i % 8)));
    EXPECT_NE(crc32(b), 0xA2F92763u) << i;
  }
}

TEST(FileLock, OneHolderAtATimeReleasedWhenTheHolderEnds) {
  const auto dir = test::scratch_dir();
  const fs::path path = dir / "run.lock";
  {
    auto first = FileLock::try_acquire(path);
    ASSERT_TRUE(first.has_value());
    EXPECT_EQ(lock_file_holder(path), static_cast<long>(::getpid()));
    EXPECT_FALSE(FileLock::try_acquire(path).has_value());  // a second open file of this process too
    FileLock moved = std::move(*first);                     // moving keeps it held
    EXPECT_FALSE(FileLock::try_acquire(path).has_value());
  }
  EXPECT_TRUE(FileLock::try_acquire(path).has_value());
  EXPECT_EQ(read_file(path), "");  // a released lock names no holder
  EXPECT_FALSE(lock_holder_running(path));

  // The holder is known by its id and start time: a process that took the id of an ended holder is not it.
  {
    const auto held = FileLock::try_acquire(path);
    ASSERT_TRUE(held.has_value());
    const unsigned long long start = process_start_time(::getpid());
    EXPECT_GT(start, 0u);
    EXPECT_EQ(read_file(path), fmt::format("{} {}\n", ::getpid(), start));
    EXPECT_TRUE(lock_holder_running(path));
  }
  write_file_atomic(path, fmt::format("{} {}\n", ::getpid(), process_start_time(::getpid()) + 1));
  EXPECT_FALSE(lock_holder_running(path));
  write_file_atomic(path, fmt::format("{}\n", ::getpid()));  // a file of an older d2gs: the id alone decides
  EXPECT_TRUE(lock_holder_running(path));
  EXPECT_EQ(process_start_time(999999999), 0u);

  // A holder killed with SIGKILL leaves no stale lock.
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  if (child == 0) {
    auto held = FileLock::try_acquire(path);
    const char c = held ? 'y' : 'n';
    [[maybe_unused]] const auto n = ::write(ready[1], &c, 1);
    ::pause();
    ::_exit(0);
  }
  char c = 0;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);
  EXPECT_EQ(c, 'y');
  EXPECT_FALSE(FileLock::try_acquire(path).has_value());
  EXPECT_EQ(lock_file_holder(path), static_cast<long>(child));
  EXPECT_TRUE(process_alive(child));
  EXPECT_TRUE(lock_holder_running(path));
  ::kill(child, SIGKILL);
  // Ended but not yet reaped (a zombie, which still answers kill(pid, 0)): not alive.
  EXPECT_TRUE(test::wait_until([&] { return !process_alive(child); }, std::chrono::seconds(10)));
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_FALSE(process_alive(child));
  EXPECT_FALSE(lock_holder_running(path));  // its id stays in the file, but no process holds it
  EXPECT_TRUE(FileLock::try_acquire(path).has_value());
  ::close(ready[0]);
  ::close(ready[1]);

  EXPECT_THROW(FileLock::try_acquire(dir / "no/such/folder/x.lock"), Error);
}

TEST(AtomicFile, StaleTemporariesOfDeadWritersAreRemoved) {
  const auto dir = test::scratch_dir();
  // The writers' own temporary names parse back to their process.
  {
    AtomicFile f(dir / "sub/point_cloud.ply");
    EXPECT_EQ(atomic_temporary_writer(f.temporary_path().filename().string()), static_cast<long>(::getpid()));
  }
  EXPECT_EQ(atomic_temporary_writer(".chkpnt300.tmp4242-17.bin"), 4242);
  EXPECT_EQ(atomic_temporary_writer(".results.tmp7-0.json"), 7);
  EXPECT_EQ(atomic_temporary_writer(".README.tmp12-3"), 12);  // a destination without extension
  for (const char* other : {"chkpnt300.bin", "chkpnt3.tmp12-0.bin", ".chkpnt3.tmp-0.bin", ".chkpnt3.tmp0-1.bin",
                            ".chkpnt3.tmp12.bin", ".chkpnt3.tmpx-1.bin", ".a.tmp12-1.tar.gz", ".tmp12-1.bin"})
    EXPECT_EQ(atomic_temporary_writer(other), 0) << other;

  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  int status = 0;
  ::waitpid(child, &status, 0);  // reaped: its id names no process now
  const std::vector<fs::path> dead = {dir / fmt::format(".chkpnt3.tmp{}-0.bin", child),
                                      dir / fmt::format("a/b/.point_cloud.tmp{}-4.ply", child)};
  const std::vector<fs::path> kept = {dir / fmt::format(".chkpnt3.tmp{}-0.bin", ::getpid()),
                                      dir / "chkpnt3.bin", dir / ".chkpnt3.tmpx-0.bin"};
  for (const auto& p : dead) write_file_atomic(p, "half");
  for (const auto& p : kept) write_file_atomic(p, "keep");
  auto removed = remove_stale_temporaries(dir);
  std::sort(removed.begin(), removed.end());
  EXPECT_EQ(removed, dead);
  for (const auto& p : dead) EXPECT_FALSE(fs::exists(p)) << p;
  for (const auto& p : kept) EXPECT_TRUE(fs::exists(p)) << p;
  EXPECT_TRUE(remove_stale_temporaries(dir).empty());
}

}  // namespace
}  // namespace d2gs
