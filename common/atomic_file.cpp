#include "common/atomic_file.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdint>
#include <fstream>
#include <string>
#include <system_error>
#include <vector>

namespace gearpulse {
namespace {

// Temp names are "<name>.tmp.XXXXXX": recognisable, so leftovers can be found and ignored.
std::string temp_prefix(const std::filesystem::path& path) {
  return path.filename().string() + ".tmp.";
}

[[noreturn]] void throw_errno(const std::string& what, const std::filesystem::path& path) {
  throw std::system_error(errno, std::generic_category(), what + " " + path.string());
}

void sync_directory(const std::filesystem::path& dir) {
  UniqueFd dfd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (dfd.get() < 0 || ::fsync(dfd.get()) != 0) throw_errno("cannot fsync directory", dir);
}

void write_all(int fd, std::string_view data, const std::filesystem::path& path) {
  std::size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw_errno("cannot write", path);
    }
    done += static_cast<std::size_t>(n);
  }
}

// The process's umask, read without changing it (umask(2) sets it, which would race with other threads
// creating files). /proc/self/status has it since Linux 4.7; 022 where it cannot be read.
mode_t process_umask() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("Umask:", 0) == 0) {
      try {
        return static_cast<mode_t>(std::stoul(line.substr(6), nullptr, 8)) & 0777;
      } catch (const std::exception&) {
        break;
      }
    }
  }
  return 022;
}

// mkostemp creates 0600: the replacement gets the mode the old file had, or a new file's.
mode_t mode_for(const std::filesystem::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) return st.st_mode & 07777;
  return 0666 & ~process_umask();
}

}  // namespace

void write_file_atomic(const std::filesystem::path& path, std::string_view data) {
  const std::filesystem::path dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  std::string tmpl = (dir / (temp_prefix(path) + "XXXXXX")).string();
  std::vector<char> name(tmpl.begin(), tmpl.end());
  name.push_back('\0');
  UniqueFd fd(::mkostemp(name.data(), O_CLOEXEC));
  if (fd.get() < 0) throw_errno("cannot create temp file for", path);
  const std::string tmp(name.data());
  // Errors name the file being written, not its temp file: the temp name is new at every attempt, and a
  // fault that repeats (a full disk) reads the same each time, so it is said once per spell.
  try {
    if (::fchmod(fd.get(), mode_for(path)) != 0) throw_errno("cannot chmod a temp file for", path);
    write_all(fd.get(), data, path);
    if (::fsync(fd.get()) != 0) throw_errno("cannot fsync", path);
    if (::close(fd.release()) != 0) throw_errno("cannot close", path);
    if (::rename(tmp.c_str(), path.c_str()) != 0) throw_errno("cannot rename into", path);
  } catch (...) {
    ::unlink(tmp.c_str());
    throw;
  }
  // The rename is durable only once the directory entry is on disk.
  try {
    sync_directory(dir);
  } catch (const std::system_error& e) {
    throw DirectorySyncError(
        e.code(), "renamed " + path.string() + " into place but cannot fsync directory " + dir.string());
  }
}

void append_file_durable(const std::filesystem::path& path, std::string_view data) {
  UniqueFd fd(::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC));
  if (fd.get() < 0) throw_errno("cannot open", path);
  write_all(fd.get(), data, path);
  if (::fdatasync(fd.get()) != 0) throw_errno("cannot fsync", path);
  if (::close(fd.release()) != 0) throw_errno("cannot close", path);
}

void remove_file_durable(const std::filesystem::path& path) {
  if (::unlink(path.c_str()) != 0) {
    if (errno == ENOENT) return;
    throw_errno("cannot remove", path);
  }
  sync_directory(path.has_parent_path() ? path.parent_path() : std::filesystem::path("."));
}

std::optional<std::string> read_file(const std::filesystem::path& path, std::size_t max_bytes) {
  std::string out;
  if (!read_file_chunks(path, max_bytes, [&out](std::string_view piece) { out.append(piece); }))
    return std::nullopt;
  return out;
}

bool read_file_chunks(const std::filesystem::path& path, std::size_t max_bytes,
                      const std::function<void(std::string_view)>& consume) {
  // O_NONBLOCK: opening a FIFO for reading otherwise waits for a writer, before fstat can refuse it.
  UniqueFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK));
  if (fd.get() < 0) {
    if (errno == ENOENT) return false;
    throw_errno("cannot open", path);
  }
  struct stat st {};
  if (::fstat(fd.get(), &st) != 0) throw_errno("cannot stat", path);
  if (S_ISDIR(st.st_mode)) throw FileRefused(path, "is a directory");
  if (!S_ISREG(st.st_mode)) throw FileRefused(path, "not a regular file");
  const auto too_long = [&] {
    return FileRefused(path, "longer than " + std::to_string(max_bytes) + " bytes, the limit for this file");
  };
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes) throw too_long();
  std::array<char, 65536> buf;
  std::size_t read = 0;
  for (;;) {
    const ssize_t n = ::read(fd.get(), buf.data(), buf.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      throw_errno("cannot read", path);
    }
    if (n == 0) break;
    read += static_cast<std::size_t>(n);
    if (read > max_bytes) throw too_long();  // it grew since fstat
    consume(std::string_view(buf.data(), static_cast<std::size_t>(n)));
  }
  return true;
}

std::size_t remove_stale_temp_files(const std::filesystem::path& path) noexcept {
  std::size_t removed = 0;
  std::error_code ec;
  const std::filesystem::path dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  const std::string prefix = temp_prefix(path);
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() == prefix.size() + 6 && name.compare(0, prefix.size(), prefix) == 0) {
      std::error_code rm;
      if (std::filesystem::remove(it->path(), rm)) ++removed;
    }
  }
  return removed;
}

DirectoryLock::DirectoryLock(const std::filesystem::path& dir) {
  const std::filesystem::path path = dir / ".lock";
  fd_.reset(::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600));
  if (!fd_) throw_errno("cannot open lock file", path);
  if (::flock(fd_.get(), LOCK_EX | LOCK_NB) == 0) {
    held_ = true;
  } else if (errno != EWOULDBLOCK) {
    // No locks on this file system (some network or FUSE mounts): say so, rather than take it for a
    // second daemon.
    const int err = errno;
    throw std::system_error(err, std::generic_category(), "cannot lock " + path.string());
  }
}

}  // namespace gearpulse
