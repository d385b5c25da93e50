#pragma once
// Atomic output: every file d2gs writes (models, images, JSON, checkpoints) goes to a temporary file in
// the destination folder and is renamed over the destination only once it is complete and flushed. A
// run killed at any moment leaves either the old file or the new one, never half of one.
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace d2gs {

class AtomicFile {
public:
  explicit AtomicFile(std::filesystem::path destination);
  ~AtomicFile();  // removes the temporary file unless commit() succeeded
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::ofstream& stream() { return stream_; }
  const std::filesystem::path& temporary_path() const { return temporary_; }
  // Flushes, syncs and renames the temporary file onto the destination. Throws d2gs::Error on failure.
  void commit();

private:
  std::filesystem::path destination_;
  std::filesystem::path temporary_;
  std::ofstream stream_;
  bool committed_ = false;
};

// The set of files one command writes, each atomically: unless the command reaches keep(), the destructor
// removes the files named here and then the folders made here that are left empty, so a command that
// fails part-way (a full disk, a bad view) leaves no partial set behind for the next run to trip over.
// Name only files the command may replace: those it checked were not there, or its own.
class OutputSet {
public:
  OutputSet() = default;
  ~OutputSet();
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;
  // Creates `dir` and its missing parents; those made here go again if they are left empty.
  void create_folder(const std::filesystem::path& dir);
  // A file about to be written; returns `path`.
  const std::filesystem::path& file(const std::filesystem::path& path);
  void keep() { kept_ = true; }

private:
  std::vector<std::filesystem::path> files_, folders_;
  bool kept_ = false;
};

// Writes `bytes` to `path` atomically.
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);
// Calls `write(temporary_path)` to produce the file under a temporary name (same extension, so that
// writers choosing a format by extension still work), then renames it onto `path`.
void write_file_atomic_with(const std::filesystem::path& path,
                            const std::function<void(const std::filesystem::path&)>& write);
// Checks, before a command does its work, that it will be able to write its outputs: `dir` is a folder,
// or can be created as one (its nearest existing ancestor is a writable folder, not a file), and a file can be
// created in that folder (tried with a probe file, removed at once: /proc or a read-only mount refuse only
// there). Throws d2gs::Error naming `dir` and the obstacle otherwise. Leaves nothing behind.
void check_output_folder(const std::filesystem::path& dir);
// The same for a file to be written: its folder is checked as above, and `file` is not a folder.
void check_output_file(const std::filesystem::path& file);
// The process id in the name of a temporary file of the writers above (".STEM.tmpPID-K.EXT", in the
// destination's folder), 0 when `filename` is not one.
long atomic_temporary_writer(const std::string& filename);
// Removes the temporary files under `dir` (recursively) whose writer is no longer running on this
// machine: what a writer killed between open and rename leaves behind. Returns the removed paths.
// Call it only while holding the folder's lock: a writer on another machine sharing the folder looks
// dead from here.
std::vector<std::filesystem::path> remove_stale_temporaries(const std::filesystem::path& dir);
// Reads a whole file; throws d2gs::Error naming the file when it cannot be read.
std::string read_file(const std::filesystem::path& path);
// Throws d2gs::Error "<path>: ..." unless `path` is a regular file (or a link to one): missing, a folder,
// or a named pipe, socket or device, which an open would block on or read without end.
void require_regular_file(const std::filesystem::path& path);

}  // namespace d2gs
