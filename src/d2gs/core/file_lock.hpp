#pragma once
// An exclusive lock on a folder or a job, as a flock(2) on a lock file: held for the lifetime of the
// FileLock object and released by the kernel when the process ends, however it ends (a crash or
// SIGKILL leaves no stale lock). The holder writes its process id and start time into the file, for the
// message of whoever finds it taken and for lock_holder_running, and empties it when it releases the lock.
// Advisory: it keeps out only the programs that take the same lock.
#include <filesystem>
#include <optional>
#include <string>

namespace d2gs {

class FileLock {
public:
  // Takes the lock on `path` (created when missing) without waiting; nullopt when another process
  // (or another FileLock of this process) holds it. Throws d2gs::Error when the file cannot be opened.
  static std::optional<FileLock> try_acquire(const std::filesystem::path& path);

  FileLock(FileLock&& other) noexcept;
  FileLock& operator=(FileLock&& other) noexcept;
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;
  // Releases the lock. A holder may remove the file before it releases it (try_acquire re-opens a path
  // whose file went while it waited); removing it after the release would race with the next holder.
  ~FileLock();

  const std::filesystem::path& path() const { return path_; }

private:
  FileLock(int fd, std::filesystem::path path) : fd_(fd), path_(std::move(path)) {}
  int fd_ = -1;
  std::filesystem::path path_;
};

// One command's claim on the folder it writes a set of files into (d2gs render's views, d2gs init's
// geometry): the lock on DIR/NAME, taken at construction or a one-line error "DIR: another WHO (process
// PID) is writing into this folder", and its file removed, while still held, at destruction, so that a
// finished command leaves nothing behind. Take it before checking which files are already there.
class FolderWriteLock {
public:
  FolderWriteLock(const std::filesystem::path& dir, const char* name, const char* who);
  ~FolderWriteLock();
  FolderWriteLock(const FolderWriteLock&) = delete;
  FolderWriteLock& operator=(const FolderWriteLock&) = delete;

private:
  std::optional<FileLock> lock_;
};

// The process id its holder wrote into the lock file at `path`, 0 when there is none.
long lock_file_holder(const std::filesystem::path& path);
// " (process PID)" of that holder for a message, or empty when the file names none.
std::string lock_holder_note(const std::filesystem::path& path);

// True when the process that took the lock on `path` still runs on this machine and has not released it:
// the file names a live process whose start time is the one recorded (a process that reused the id of an
// ended holder is not it). A holder on another machine sharing the folder is not seen.
bool lock_holder_running(const std::filesystem::path& path);

// The start time of process `pid` in clock ticks after boot (/proc/PID/stat), 0 when unknown.
unsigned long long process_start_time(long pid);

// True when a process with this id runs on this machine (an ended process its parent has not reaped yet,
// a zombie, does not).
bool process_alive(long pid);

}  // namespace d2gs
