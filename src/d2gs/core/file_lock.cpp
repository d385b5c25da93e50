#include "d2gs/core/file_lock.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "d2gs/core/error.hpp"

namespace d2gs {
namespace fs = std::filesystem;

std::optional<FileLock> FileLock::try_acquire(const fs::path& path) {
  // The lock is on the file the path names when it is taken: a holder may remove its lock file while it
  // holds it (a run that leaves nothing behind), and a process that opened that file just before would
  // otherwise hold a lock on a file no one else can see. Such a lock is dropped and the path opened again.
  int fd = -1;
  for (int attempt = 0;; ++attempt) {
    fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) fail_file(path, "cannot open the lock file ({})", std::strerror(errno));
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      ::close(fd);
      if (err == EWOULDBLOCK) return std::nullopt;
      fail_file(path, "cannot lock ({})", std::strerror(err));
    }
    struct stat held {}, named {};
    if (::fstat(fd, &held) == 0 && ::stat(path.c_str(), &named) == 0 && held.st_dev == named.st_dev &&
        held.st_ino == named.st_ino)
      break;
    ::close(fd);
    if (attempt == 100) fail_file(path, "cannot lock: the lock file keeps being replaced");
  }
  const long self = static_cast<long>(::getpid());
  const std::string holder = fmt::format("{} {}\n", self, process_start_time(self));
  if (::ftruncate(fd, 0) == 0) {
    [[maybe_unused]] const auto written = ::pwrite(fd, holder.data(), holder.size(), 0);
  }
  return FileLock(fd, path);
}

namespace {
// Empties the lock file (it names no holder any more) and closes it, which releases the flock.
void release(int fd) {
  [[maybe_unused]] const int cleared = ::ftruncate(fd, 0);
  ::close(fd);
}
}  // namespace

FileLock::FileLock(FileLock&& other) noexcept : fd_(other.fd_), path_(std::move(other.path_)) { other.fd_ = -1; }

FileLock& FileLock::operator=(FileLock&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) release(fd_);
    fd_ = other.fd_;
    path_ = std::move(other.path_);
    other.fd_ = -1;
  }
  return *this;
}

FileLock::~FileLock() {
  if (fd_ >= 0) release(fd_);  // closing the last descriptor of the open file releases the flock
}

FolderWriteLock::FolderWriteLock(const fs::path& dir, const char* name, const char* who)
    : lock_(FileLock::try_acquire(dir / name)) {
  if (!lock_) fail_file(dir, "another {}{} is writing into this folder", who, lock_holder_note(dir / name));
}

FolderWriteLock::~FolderWriteLock() {
  std::error_code ec;
  if (lock_) fs::remove(lock_->path(), ec);  // while held: try_acquire re-opens a path whose file went
}

long lock_file_holder(const fs::path& path) {
  std::ifstream in(path);
  long pid = 0;
  if (!(in >> pid) || pid <= 0) return 0;
  return pid;
}

std::string lock_holder_note(const fs::path& path) {
  const long pid = lock_file_holder(path);
  return pid > 0 ? fmt::format(" (process {})", pid) : std::string();
}

unsigned long long process_start_time(long pid) {
  if (pid <= 0) return 0;
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(stat, text)) return 0;
  const std::size_t close = text.rfind(')');  // the command name may hold spaces and parentheses
  if (close == std::string::npos) return 0;
  std::istringstream fields(text.substr(close + 1));
  std::string field;
  for (int k = 3; k < 22 && (fields >> field); ++k) {
  }  // fields 3 (state) to 21
  unsigned long long start = 0;
  return (fields >> start) ? start : 0;  // field 22: starttime
}

bool lock_holder_running(const fs::path& path) {
  std::ifstream in(path);
  long pid = 0;
  if (!(in >> pid) || pid <= 0 || !process_alive(pid)) return false;
  unsigned long long recorded = 0;
  if (!(in >> recorded) || recorded == 0) return true;  // no start time recorded: the id alone decides
  const unsigned long long now = process_start_time(pid);
  return now == 0 || now == recorded;
}

bool process_alive(long pid) {
  if (pid <= 0) return false;
  if (::kill(static_cast<pid_t>(pid), 0) != 0 && errno != EPERM) return false;
  // A process that has ended but is not yet reaped by its parent (a zombie) still answers kill(pid, 0);
  // /proc/PID/stat's state after the parenthesised command name says so ('Z', or 'X' while it goes).
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(stat, text)) return true;  // no /proc: trust kill()
  const std::size_t close = text.rfind(')');
  if (close == std::string::npos || close + 2 >= text.size()) return true;
  const char state = text[close + 2];
  return state != 'Z' && state != 'X';
}

}  // namespace d2gs
