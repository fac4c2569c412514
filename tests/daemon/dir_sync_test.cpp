// A directory or a file that cannot be synced (an I/O error on the medium): what the daemon writes is
// durable only once it is synced, so a sync that fails is an error, and where a file was already renamed
// into place, what the daemon knows of its files must say so. This executable's own fsync() and
// fdatasync() stand in front of the C library's (the daemon's code is linked in statically) and fail on
// a directory, or on a regular file, while a test asks them to.
#include <catch2/catch.hpp>

#include <dlfcn.h>
#include <sys/stat.h>

#include <atomic>
#include <cerrno>
#include <memory>
#include <string>

#include "common/atomic_file.hpp"
#include "daemon/model_store.hpp"
#include "daemon/training_store.hpp"
#include "tests/test_util.hpp"

namespace {
std::atomic<bool> fail_directory_sync{false};
std::atomic<bool> fail_file_sync{false};

// Fails directory syncs while it lives.
struct FailingDirectorySync {
  FailingDirectorySync() { fail_directory_sync = true; }
  ~FailingDirectorySync() { fail_directory_sync = false; }
  FailingDirectorySync(const FailingDirectorySync&) = delete;
  FailingDirectorySync& operator=(const FailingDirectorySync&) = delete;
};

// Fails the syncs of regular files (fsync and fdatasync) while it lives.
struct FailingFileSync {
  FailingFileSync() { fail_file_sync = true; }
  ~FailingFileSync() { fail_file_sync = false; }
  FailingFileSync(const FailingFileSync&) = delete;
  FailingFileSync& operator=(const FailingFileSync&) = delete;
};

// Whether a sync of `fd` is to fail now.
bool sync_fails(int fd) {
  struct stat st {};
  if (!fail_directory_sync && !fail_file_sync) return false;
  if (::fstat(fd, &st) != 0) return false;
  return (fail_directory_sync && S_ISDIR(st.st_mode)) || (fail_file_sync && S_ISREG(st.st_mode));
}
}  // namespace

extern "C" int fsync(int fd) {
  if (sync_fails(fd)) {
    errno = EIO;
    return -1;
  }
  using Fn = int (*)(int);
  static const auto real = reinterpret_cast<Fn>(::dlsym(RTLD_NEXT, "fsync"));
  return real(fd);
}

extern "C" int fdatasync(int fd) {
  if (sync_fails(fd)) {
    errno = EIO;
    return -1;
  }
  using Fn = int (*)(int);
  static const auto real = reinterpret_cast<Fn>(::dlsym(RTLD_NEXT, "fdatasync"));
  return real(fd);
}

using gearpulse::DirectorySyncError;
using gearpulse::daemon::TrainingStore;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::write_text;

TEST_CASE("state: a training store renamed into place whose directory cannot be synced is the saved one") {
  TempDir dir;
  const auto path = dir / "training.bin";
  TrainingStore store(1e9, 1000);
  for (int i = 0; i < 10; ++i)
    store.add({double(i), 10.0, 50.0});
  store.save(path);
  for (int i = 10; i < 15; ++i)
    store.add({double(i), 10.0, 50.0});
  {
    const FailingDirectorySync failing;
    CHECK_THROWS_AS(store.save(path), DirectorySyncError);
  }
  // The file holds 15 pairs; a journal written now must extend that file, not the one it replaced.
  for (int i = 15; i < 18; ++i)
    store.add({double(i), 10.0, 50.0});
  CHECK(store.append_journal(path) == 3);
  TrainingStore back(1e9, 1000);
  REQUIRE(back.load(path).empty());
  CHECK(back.size() == 15);
  CHECK(back.replay_journal(path).recovered == 3);
  CHECK(back.size() == 18);
}

TEST_CASE("state: a model renamed into place whose directory cannot be synced is still the daemon's own") {
  TempDir dir;
  const auto path = dir / "model.json";
  gearpulse::daemon::ModelHolder holder;
  gearpulse::GearModel model;
  model.gears = {{0.05, 0.5, 0.0001}, {0.08, 0.5, 0.0001}};
  model.samples = 100;
  {
    const FailingDirectorySync failing;
    CHECK_THROWS_AS(gearpulse::daemon::save_model_if_ours(holder, path, model), DirectorySyncError);
  }
  // The next fit's model goes over it: the file is not one another program put there.
  model.samples = 200;
  CHECK(gearpulse::daemon::save_model_if_ours(holder, path, model) == gearpulse::daemon::ModelSave::kSaved);
}

// A temp file renamed over model.json before its data is on disk can leave an empty model.json after a
// power cut: a save whose file will not sync fails there, and the old model stays in place.
TEST_CASE("state: a file whose data cannot be synced is not renamed into place") {
  TempDir dir;
  const auto path = dir / "model.json";
  gearpulse::write_file_atomic(path, "the old model");
  {
    const FailingFileSync failing;
    try {
      gearpulse::write_file_atomic(path, "the new model");
      FAIL("no error");
    } catch (const DirectorySyncError&) {
      FAIL("renamed into place before its data was synced");
    } catch (const std::system_error& e) {
      CHECK(std::string(e.what()).find("cannot fsync " + path.string()) == 0);
    }
  }
  CHECK(read_text(path) == "the old model");
  CHECK(std::distance(std::filesystem::directory_iterator(dir.path()), {}) == 1);  // no temp file left
}

// Pairs journaled are counted as kept: an append whose data will not sync has kept nothing, and the
// journal is written again at the next try.
TEST_CASE("state: a journal append that cannot be synced fails and keeps its pairs to be journaled") {
  TempDir dir;
  const auto path = dir / "training.bin";
  const auto journal = TrainingStore::journal_path(path);
  TrainingStore store(1e9, 1000);
  for (int i = 0; i < 10; ++i)
    store.add({double(i), 10.0, 50.0});
  store.save(path);
  write_text(dir / "log", "first line\n");
  for (int i = 10; i < 15; ++i)
    store.add({double(i), 10.0, 50.0});
  {
    const FailingFileSync failing;
    try {
      gearpulse::append_file_durable(dir / "log", "second line\n");
      FAIL("no error");
    } catch (const std::system_error& e) {
      CHECK(std::string(e.what()).find("cannot fsync " + (dir / "log").string()) == 0);
    }
    CHECK_THROWS_AS(store.append_journal(path), std::system_error);
    CHECK(store.unkept() == 5);
  }
  CHECK(store.append_journal(path) == 5);
  TrainingStore back(1e9, 1000);
  REQUIRE(back.load(path).empty());
  CHECK(back.replay_journal(path).recovered == 5);
}

// A removal is durable only once its directory is synced: a cleared journal that comes back after a
// power cut would bring back the pairs a reset cleared.
TEST_CASE("state: a file removed from a directory that cannot be synced is an error") {
  TempDir dir;
  const auto path = dir / "training.bin.journal";
  write_text(path, "pairs");
  {
    const FailingDirectorySync failing;
    try {
      gearpulse::remove_file_durable(path);
      FAIL("no error");
    } catch (const std::system_error& e) {
      CHECK(std::string(e.what()).find("cannot fsync directory") != std::string::npos);
    }
  }
  // The save after a reset removes the old journal first; it is not counted as done.
  TrainingStore store(1e9, 1000);
  for (int i = 0; i < 10; ++i)
    store.add({double(i), 10.0, 50.0});
  store.save(dir / "training.bin");
  store.clear();
  {
    const FailingDirectorySync failing;
    CHECK_THROWS_MATCHES(
        store.save(dir / "training.bin"), std::system_error,
        Catch::Matchers::Predicate<std::system_error>(
            [](const std::system_error& e) { return dynamic_cast<const DirectorySyncError*>(&e) == nullptr; },
            "not a DirectorySyncError"));
  }
  CHECK(store.unsaved());
}
