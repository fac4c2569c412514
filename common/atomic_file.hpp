#pragma once
// Files that must survive a power cut: a car PC loses power without warning, so a reader sees either
// the old content or the new one, never a torn mix.
#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>

#include "drivers/unique_fd.hpp"

namespace gearpulse {

// The new file is in place (readers see it) but its directory could not be synced: a power cut may still
// bring back the old one. Callers that track what the file holds must count it as written.
struct DirectorySyncError : std::system_error {
  using std::system_error::system_error;
};

// Writes `data` to a temp file in the same directory, fsyncs it, renames it over `path` and fsyncs the
// directory. Throws std::system_error naming the path on failure: the old file is then untouched, except
// for a DirectorySyncError, thrown after the rename.
// A file that exists keeps its permissions; a new one gets those of a file created under the process's
// umask (0644 under 022, 0640 under the unit's 0027).
void write_file_atomic(const std::filesystem::path& path, std::string_view data);

// Appends `data` to the existing file `path` and fdatasyncs it: a journal's records are on disk when this
// returns. A power cut during the call may leave part of `data` at the end (readers check each record).
// Throws std::system_error naming the path on failure, including when the file does not exist.
void append_file_durable(const std::filesystem::path& path, std::string_view data);

// Removes `path` (nothing to do if it is absent) and fsyncs its directory, so the removal survives a power
// cut. Throws std::system_error naming the path on failure.
void remove_file_durable(const std::filesystem::path& path);

// A file that is there but is not read: not a regular file (a FIFO blocks its reader, a device like
// /dev/zero never ends), or longer than the reader takes. reason() says which, without the path.
class FileRefused : public std::runtime_error {
 public:
  FileRefused(const std::filesystem::path& path, std::string reason)
      : std::runtime_error(path.string() + ": " + reason), reason_(std::move(reason)) {}
  [[nodiscard]] const std::string& reason() const noexcept { return reason_; }

 private:
  std::string reason_;
};

// Whole file, or nullopt if it does not exist. Throws FileRefused for anything but a regular file and for
// a file longer than `max_bytes` (so no file makes the reader allocate more than that), std::system_error
// on other open and read errors.
[[nodiscard]] std::optional<std::string> read_file(const std::filesystem::path& path, std::size_t max_bytes);
// The same checks, the file handed to `consume` in pieces of up to 64 KiB as it is read, so that a reader
// that keeps only part of it holds no more than that part. False if the file does not exist.
bool read_file_chunks(const std::filesystem::path& path, std::size_t max_bytes,
                      const std::function<void(std::string_view)>& consume);

// Removes temp files that a crash between create and rename left behind next to `path`.
// Returns how many were removed.
std::size_t remove_stale_temp_files(const std::filesystem::path& path) noexcept;

// An exclusive lock on a directory (flock on DIR/.lock), held while the object lives: one daemon per
// state directory, so a second one started by mistake cannot remove the first one's temp files in the
// middle of a save, nor overwrite what it saves. Released when the process dies, however it dies.
class DirectoryLock {
 public:
  // Throws std::system_error naming the lock file when it cannot be opened or the file system has no
  // locks; held() is false only when another process holds the lock.
  explicit DirectoryLock(const std::filesystem::path& dir);
  DirectoryLock(const DirectoryLock&) = delete;
  DirectoryLock& operator=(const DirectoryLock&) = delete;
  // False when another process holds the lock.
  [[nodiscard]] bool held() const noexcept { return held_; }

 private:
  UniqueFd fd_;  // closing it releases the lock
  bool held_ = false;
};

}  // namespace gearpulse
