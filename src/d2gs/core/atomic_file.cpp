#include "d2gs/core/atomic_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <regex>
#include <system_error>

#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"

namespace d2gs {
namespace fs = std::filesystem;

namespace {

fs::path temporary_name(const fs::path& destination) {
  static std::atomic<unsigned> counter{0};
  const auto stem = destination.stem().string();
  const auto ext = destination.extension().string();
  return destination.parent_path() /
         fmt::format(".{}.tmp{}-{}{}", stem, static_cast<long>(::getpid()), counter++, ext);
}

void ensure_parent(const fs::path& destination) {
  const auto parent = destination.parent_path();
  if (parent.empty()) return;
  std::error_code ec;
  fs::create_directories(parent, ec);
  if (ec) fail_file(parent, "cannot create folder: {}", ec.message());
}

// Flushes the written file to the disk. Where the storage reports the data lost (a network or quota file
// system can say so only now), the temporary goes and the write fails; a file system that cannot sync
// (EINVAL, EROFS...) keeps the file as written.
void sync_file(const fs::path& temporary, const fs::path& destination) {
  const int fd = ::open(temporary.c_str(), O_RDONLY);
  if (fd < 0) return;
  const auto lost_data = [](int result) {  // the errno of a failed call that reports lost data, else 0
    return result != 0 && (errno == EIO || errno == ENOSPC || errno == EDQUOT) ? errno : 0;
  };
  int lost = lost_data(::fsync(fd));
  if (const int on_close = lost_data(::close(fd)); lost == 0) lost = on_close;
  if (lost != 0) {
    std::error_code ec;
    fs::remove(temporary, ec);
    fail_file(destination, "write failed: {}", std::strerror(lost));
  }
}

void rename_into_place(const fs::path& temporary, const fs::path& destination) {
  std::error_code ec;
  fs::rename(temporary, destination, ec);
  if (ec) {
    const std::string why = ec.message();  // before the removal can touch errno
    fs::remove(temporary, ec);
    fail_file(destination, "cannot write: {}", why);
  }
}

}  // namespace

AtomicFile::AtomicFile(fs::path destination)
    : destination_(std::move(destination)), temporary_(temporary_name(destination_)) {
  ensure_parent(destination_);
  stream_.open(temporary_, std::ios::binary | std::ios::trunc);
  if (!stream_) fail_file(destination_, "cannot open for writing: {}", std::strerror(errno));
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    stream_.close();
    std::error_code ec;
    fs::remove(temporary_, ec);
  }
}

void AtomicFile::commit() {
  stream_.flush();
  bool ok = static_cast<bool>(stream_);
  stream_.close();  // the last buffered bytes are written here: a failure sets failbit
  ok = ok && !stream_.fail();
  if (!ok) fail_file(destination_, "write failed (disk full?)");  // the destructor removes the temporary
  sync_file(temporary_, destination_);
  rename_into_place(temporary_, destination_);
  committed_ = true;
}

OutputSet::~OutputSet() {
  if (kept_) return;
  std::error_code ec;
  for (auto it = files_.rbegin(); it != files_.rend(); ++it) fs::remove(*it, ec);
  for (auto it = folders_.rbegin(); it != folders_.rend(); ++it)
    if (fs::is_directory(*it, ec) && fs::is_empty(*it, ec)) fs::remove(*it, ec);
}

void OutputSet::create_folder(const fs::path& dir) {
  std::vector<fs::path> missing;
  std::error_code ec;
  for (fs::path p = dir; !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    missing.push_back(p);
    if (p == p.parent_path()) break;
  }
  fs::create_directories(dir, ec);
  if (ec) fail_file(dir, "cannot create folder: {}", ec.message());
  folders_.insert(folders_.end(), missing.rbegin(), missing.rend());  // outermost first, removed last
}

const fs::path& OutputSet::file(const fs::path& path) {
  files_.push_back(path);
  return path;
}

void write_file_atomic(const fs::path& path, std::string_view bytes) {
  AtomicFile file(path);
  file.stream().write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  file.commit();
}

void write_file_atomic_with(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  ensure_parent(path);
  const auto temporary = temporary_name(path);
  try {
    write(temporary);
  } catch (...) {
    std::error_code ec;
    fs::remove(temporary, ec);
    throw;
  }
  std::error_code ec;
  if (!fs::exists(temporary, ec)) fail_file(path, "writer produced no file");
  sync_file(temporary, path);
  rename_into_place(temporary, path);
}

namespace {

// Why no file can be created in the existing folder `dir`, or empty: a probe file (named as temporary_name()
// names them, so that remove_stale_temporaries finds one a killed process left) created and removed. access()
// is not enough: it says yes to root everywhere, and /proc or a read-only mount refuse only at the create.
std::string create_obstacle(const fs::path& dir) {
  const fs::path probe = temporary_name(dir / ".d2gs-write-probe");
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) return fmt::format("folder {} is not writable ({})", dir.string(), std::strerror(errno));
  ::close(fd);
  ::unlink(probe.c_str());
  return {};
}

// Why folder `dir` cannot be written to or created, or empty.
std::string folder_obstacle(const fs::path& dir) {
  if (dir.empty()) return {};  // the working folder
  std::error_code ec;
  const fs::path path = fs::absolute(dir, ec);
  if (ec) return fmt::format("cannot resolve the path: {}", ec.message());
  if (fs::exists(path, ec)) {
    if (!fs::is_directory(path, ec)) return fmt::format("{} exists and is not a folder", path.string());
    if (::access(path.c_str(), W_OK | X_OK) != 0)
      return fmt::format("folder {} is not writable ({})", path.string(), std::strerror(errno));
    return create_obstacle(path);
  }
  // Neither there nor creatable: a loop of symbolic links, or a link to nothing (create_directories fails
  // on both, after the work).
  if (ec) return fmt::format("cannot resolve {} ({})", path.string(), ec.message());
  if (fs::is_symlink(fs::symlink_status(path, ec)))
    return fmt::format("{} is a symbolic link to {}, which does not exist", path.string(), fs::read_symlink(path, ec).string());
  for (fs::path a = path.parent_path();; a = a.parent_path()) {
    if (fs::exists(a, ec)) {
      if (!fs::is_directory(a, ec)) return fmt::format("{} is a file, not a folder", a.string());
      if (::access(a.c_str(), W_OK | X_OK) != 0)
        return fmt::format("folder {} is not writable ({})", a.string(), std::strerror(errno));
      return create_obstacle(a);
    }
    if (a == a.parent_path()) return {};
  }
}

}  // namespace

void check_output_folder(const fs::path& dir) {
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec)) fail_file(dir, "exists and is not a folder");
  if (const auto why = folder_obstacle(dir); !why.empty()) fail_file(dir, "cannot write here: {}", why);
}

void check_output_file(const fs::path& file) {
  std::error_code ec;
  if (file.empty()) fail("an output file name is empty");
  if (fs::is_directory(file, ec)) fail_file(file, "is a folder; expected a file name to write");
  if (const auto why = folder_obstacle(fs::absolute(file, ec).parent_path()); !why.empty())
    fail_file(file, "cannot write here: {}", why);
  if (fs::exists(file, ec) && ::access(file.c_str(), W_OK) != 0)
    fail_file(file, "is not writable: {}", std::strerror(errno));
}

long atomic_temporary_writer(const std::string& filename) {
  // temporary_name(): "." + stem + ".tmp" + pid + "-" + counter + extension (none, or one dot and no other).
  static const std::regex pattern(R"(\..+\.tmp([1-9][0-9]{0,9})-[0-9]+(\.[^.]*)?)");
  std::smatch m;
  if (!std::regex_match(filename, m, pattern)) return 0;
  return std::stol(m[1].str());
}

std::vector<fs::path> remove_stale_temporaries(const fs::path& dir) {
  std::vector<fs::path> stale;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec)) {
    if (!it->is_regular_file(ec) || it->is_symlink(ec)) continue;
    const long pid = atomic_temporary_writer(it->path().filename().string());
    if (pid > 0 && pid != static_cast<long>(::getpid()) && !process_alive(pid)) stale.push_back(it->path());
  }
  std::vector<fs::path> removed;
  for (const auto& p : stale)
    if (fs::remove(p, ec)) removed.push_back(p);
  return removed;
}

void require_regular_file(const fs::path& path) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  switch (st.type()) {
    case fs::file_type::regular: return;
    case fs::file_type::directory: fail_file(path, "is a folder, expected a file");
    case fs::file_type::fifo: fail_file(path, "is a named pipe, expected a file");
    case fs::file_type::socket: fail_file(path, "is a socket, expected a file");
    case fs::file_type::block:
    case fs::file_type::character: fail_file(path, "is a device, expected a file");
    case fs::file_type::not_found: fail_file(path, "file not found");
    default:
      if (ec) fail_file(path, "cannot be read: {}", ec.message());  // e.g. a loop of symbolic links
      fail_file(path, "is not a regular file");
  }
}

std::string read_file(const fs::path& path) {
  require_regular_file(path);
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) fail_file(path, "cannot open: {}", std::strerror(errno));
  const std::streamoff size = in.tellg();
  if (size < 0) fail_file(path, "cannot determine the file size");
  std::string bytes(static_cast<std::size_t>(size), '\0');
  in.seekg(0);
  if (!in.read(bytes.data(), size)) fail_file(path, "read error");
  return bytes;
}

}  // namespace d2gs
