// A directory that cannot be synced after a file was renamed into it (an I/O error on the medium): the
// new file is in place, and what the daemon knows of its files must say so. This executable's own fsync()
// stands in front of the C library's (the daemon's code is linked in statically) and fails on a directory
// while a test asks it to.
#include <catch2/catch.hpp>

#include <dlfcn.h>
#include <sys/stat.h>

#include <atomic>
#include <cerrno>
#include <memory>

#include "daemon/atomic_file.hpp"
#include "daemon/model_store.hpp"
#include "daemon/training_store.hpp"
#include "tests/test_util.hpp"

namespace {
std::atomic<bool> fail_directory_sync{false};

// Fails directory syncs while it lives.
struct FailingDirectorySync {
  FailingDirectorySync() { fail_directory_sync = true; }
  ~FailingDirectorySync() { fail_directory_sync = false; }
  FailingDirectorySync(const FailingDirectorySync&) = delete;
  FailingDirectorySync& operator=(const FailingDirectorySync&) = delete;
};
}  // namespace

extern "C" int fsync(int fd) {
  struct stat st {};
  if (fail_directory_sync && ::fstat(fd, &st) == 0 && S_ISDIR(st.st_mode)) {
    errno = EIO;
    return -1;
  }
  using Fn = int (*)(int);
  static const auto real = reinterpret_cast<Fn>(::dlsym(RTLD_NEXT, "fsync"));
  return real(fd);
}

using gearpulse::daemon::DirectorySyncError;
using gearpulse::daemon::TrainingStore;
using gearpulse::test::TempDir;

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
