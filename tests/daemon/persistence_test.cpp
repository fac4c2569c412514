#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <stdexcept>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/atomic_file.hpp"
#include "core/estimator.hpp"
#include "daemon/fitter.hpp"
#include "daemon/model_store.hpp"
#include "daemon/retrainer.hpp"
#include "daemon/training_store.hpp"
#include "tests/daemon/log_lines.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

using namespace gearpulse;
using namespace gearpulse::daemon;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::write_text;

namespace {

std::size_t count_entries(const std::filesystem::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir))
    ++n;
  return n;
}

GearModel three_gears() {
  GearModel m;
  m.gears = {{0.05, 0.3, 0.001}, {0.09, 0.4, 0.001}, {0.14, 0.3, 0.002}};
  m.samples = 1000;
  m.sigma_speed = 0.3;
  m.sigma_freq = 0.5;
  return m;
}

// A fitter that counts its calls in `fits` and finds three gears.
Retrainer::Fitter counting_fitter(std::atomic<int>& fits) {
  return [&fits](std::span<const Sample>, std::stop_token) {
    ++fits;
    return three_gears();
  };
}

// Waits up to 5 s for a first fit.
void wait_for_a_fit(const std::atomic<int>& fits) {
  for (int i = 0; i < 500 && fits.load() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
}

// Writes past `bytes` fail with EFBIG while it lives (SIGXFSZ ignored): a full disk for the writes of this
// process, which works for root too.
struct FileSizeLimit {
  rlimit old{};
  struct sigaction old_action {};
  explicit FileSizeLimit(rlim_t bytes) {
    struct sigaction ignore {};
    ignore.sa_handler = SIG_IGN;
    REQUIRE(::sigaction(SIGXFSZ, &ignore, &old_action) == 0);
    REQUIRE(::getrlimit(RLIMIT_FSIZE, &old) == 0);
    rlimit low = old;
    low.rlim_cur = bytes;
    REQUIRE(::setrlimit(RLIMIT_FSIZE, &low) == 0);
  }
  ~FileSizeLimit() {
    ::setrlimit(RLIMIT_FSIZE, &old);
    ::sigaction(SIGXFSZ, &old_action, nullptr);
  }
  FileSizeLimit(const FileSizeLimit&) = delete;
  FileSizeLimit& operator=(const FileSizeLimit&) = delete;
};

}  // namespace

TEST_CASE("daemon: atomic write replaces the content and leaves no temp file") {
  TempDir dir;
  const auto file = dir / "model.json";
  write_file_atomic(file, "first");
  CHECK(read_text(file) == "first");
  write_file_atomic(file, "second, longer content");
  CHECK(read_text(file) == "second, longer content");
  CHECK(count_entries(dir.path()) == 1);
  CHECK(read_file(dir / "absent", 1).has_value() == false);
}

TEST_CASE("daemon: atomic write gives a new file the umask's permissions and keeps an old file's") {
  TempDir dir;
  const auto file = dir / "model.json";
  const auto perms = [&] { return std::filesystem::status(file).permissions(); };
  using P = std::filesystem::perms;
  const mode_t old_mask = ::umask(027);
  write_file_atomic(file, "first");
  ::umask(old_mask);
  CHECK(perms() == (P::owner_read | P::owner_write | P::group_read));
  std::filesystem::permissions(file, P::owner_read | P::owner_write);
  write_file_atomic(file, "second");
  CHECK(perms() == (P::owner_read | P::owner_write));
  CHECK(read_text(file) == "second");
}

TEST_CASE("daemon: atomic write into a missing directory fails and names the path") {
  TempDir dir;
  try {
    write_file_atomic(dir / "missing/model.json", "x");
    FAIL("no error");
  } catch (const std::system_error& e) {
    CHECK(std::string(e.what()).find("missing/model.json") != std::string::npos);
  }
}

TEST_CASE("daemon: a write that fails for room names the file written, the same at every attempt") {
  // A save failing every few minutes on a full disk is said once per spell, which needs the same words
  // each time: the temp file's name, new at every attempt, once made every failure news.
  TempDir dir;
  const auto path = dir / "training.bin";
  std::vector<std::string> errors;
  {
    const FileSizeLimit limit(1024);
    for (int attempt = 0; attempt < 2; ++attempt) {
      try {
        write_file_atomic(path, std::string(4096, 'x'));
      } catch (const std::system_error& e) {
        errors.push_back(e.what());
      }
    }
  }
  REQUIRE(errors.size() == 2);
  CHECK(errors[0] == errors[1]);
  CHECK(errors[0].find(path.string() + ":") != std::string::npos);
  CHECK(errors[0].find(".tmp.") == std::string::npos);
  CHECK(count_entries(dir.path()) == 0);
}

TEST_CASE("daemon: atomic write survives a crash at any moment") {
  TempDir dir;
  const auto file = dir / "store.bin";
  // Two contents large enough that a write takes many syscalls; a reader must only ever see one of them.
  const std::string a(1 << 20, 'a');
  const std::string b(1 << 20, 'b');
  write_file_atomic(file, a);
  std::mt19937 rng(12345);
  for (int round = 0; round < 6; ++round) {
    const pid_t child = ::fork();
    if (child == 0) {
      for (int i = 0;; ++i)
        write_file_atomic(file, i % 2 ? a : b);
    }
    std::this_thread::sleep_for(
        std::chrono::microseconds(std::uniform_int_distribution<int>(2000, 40000)(rng)));
    ::kill(child, SIGKILL);
    ::waitpid(child, nullptr, 0);
    const std::string seen = read_text(file);
    INFO("round " << round << ": " << seen.size() << " bytes");
    CHECK((seen == a || seen == b));
  }
  // Temp files a killed writer left behind are recognised, ignored by readers and cleaned up.
  write_text(dir / "store.bin.tmp.Xy12Zq", "partial");
  CHECK(remove_stale_temp_files(file) >= 1);
  CHECK(count_entries(dir.path()) == 1);
}

// Only names the daemon's own temp files take ("NAME.tmp." and six characters) are cleaned up at start: a
// copy a user kept beside the store under a name like it is theirs, and stays.
TEST_CASE("daemon: stale temp cleanup leaves a user's files that merely look like temp files") {
  TempDir dir;
  const auto file = dir / "training.bin";
  write_text(file, "store");
  write_text(dir / "training.bin.tmp.keep", "a user's copy");
  write_text(dir / "training.bin.tmp.Xy12Zq.old", "another");
  write_text(dir / "training.bin.tmp.Xy12Zq", "partial");
  CHECK(remove_stale_temp_files(file) == 1);
  CHECK(read_text(dir / "training.bin.tmp.keep") == "a user's copy");
  CHECK(read_text(dir / "training.bin.tmp.Xy12Zq.old") == "another");
  CHECK_FALSE(std::filesystem::exists(dir / "training.bin.tmp.Xy12Zq"));
}

TEST_CASE("daemon: training store is bounded by age and by count") {
  TrainingStore store(100.0, 1000);
  for (int i = 0; i < 300; ++i)
    CHECK(store.add({1000.0 + i, 10.0, 100.0}));
  // Only the last 100 s relative to the newest pair remain.
  CHECK(store.size() == 101);
  CHECK(store.snapshot().front().t == Approx(1199.0));
  store.set_limits(1e9, 50);
  CHECK(store.size() == 50);
  CHECK(store.snapshot().front().t == Approx(1250.0));
  // Incomplete or implausible pairs are refused.
  CHECK_FALSE(store.add({1.0, kMissing, 50.0}));
  CHECK_FALSE(store.add({1.0, 5.0, kMissing}));
  CHECK_FALSE(store.add({1.0, -1.0, 50.0}));
  CHECK_FALSE(store.add({1.0, 10.0, 0.0}));  // moving with no engine frequency: no gear gives that
  CHECK(store.size() == 50);
}

// A car PC's wall clock may be days apart between two pairs (the car parked) or jump by years (no RTC
// battery, then set from GPS): neither ages the pairs. Judged against the newest pair's time, one pair
// after a weekend parked left a store of one pair, and one stamped years ahead stopped all pruning.
TEST_CASE("daemon: training store ages pairs by driving time, not by the wall clock") {
  TrainingStore store(100.0, 1000);
  for (int i = 0; i < 50; ++i)
    store.add({1000.0 + i, 10.0, 100.0});
  SECTION("parked for 60 h") {
    store.add({1049.0 + 60 * 3600.0, 10.0, 100.0});
    CHECK(store.size() == 51);
  }
  SECTION("the clock set back by years") {
    store.add({1049.0 - 3 * 365 * 86400.0, 10.0, 100.0});
    CHECK(store.size() == 51);
  }
  SECTION("a pair stamped years ahead, then driving on: still bounded") {
    store.add({1049.0 + 5 * 365 * 86400.0, 10.0, 100.0});
    for (int i = 0; i < 300; ++i)
      store.add({2000.0 + i, 10.0, 100.0});
    CHECK(store.size() == 101);  // 100 s of driving and the pair it starts from
    CHECK(store.snapshot().front().t == Approx(2199.0));
  }
  SECTION("and the same after a save and a load") {
    TempDir dir;
    store.add({1049.0 + 60 * 3600.0, 10.0, 100.0});
    store.save(dir / "training.bin");
    TrainingStore back(100.0, 1000);
    REQUIRE(back.load(dir / "training.bin").empty());
    CHECK(back.size() == 51);
    for (int i = 1; i <= 60; ++i)
      back.add({1049.0 + 60 * 3600.0 + i, 10.0, 100.0});
    CHECK(back.size() == 92);  // 49 s + 10 s (the parked step) + 60 s = 119 s: the 19 oldest went
  }
}

TEST_CASE("daemon: training store counts new pairs for the retrainer") {
  TrainingStore store(1e9, 1000);
  for (int i = 0; i < 10; ++i)
    store.add({double(i), 1.0, 10.0});
  CHECK(store.new_samples() == 10);
  store.mark_trained(7);
  CHECK(store.new_samples() == 3);
}

TEST_CASE("daemon: training store round-trips through its file") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 500; ++i)
    store.add({1.7e9 + i * 0.5, 0.1 * i, 20.0 + i * 0.25});
  store.save(dir / "training.bin");
  TrainingStore back(1e9, 10000);
  CHECK(back.load(dir / "training.bin").empty());
  const auto a = store.snapshot();
  const auto b = back.snapshot();
  REQUIRE(a.size() == b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i].t == b[i].t);
    CHECK(a[i].speed == b[i].speed);
    CHECK(a[i].freq == b[i].freq);
  }
  // A missing file is an empty store, not an error.
  TrainingStore none(1e9, 10);
  CHECK(none.load(dir / "absent.bin").empty());
  CHECK(none.size() == 0);
}

namespace {

double pair_time(int i) {
  return 1.7e9 + i;
}

void add_pairs(TrainingStore& store, int from, int to) {
  for (int i = from; i < to; ++i)
    store.add({pair_time(i), 0.1 * i, 20.0 + i});
}

// What a restart after a power cut sees: the file and the journal as they are on disk.
std::unique_ptr<TrainingStore> restarted(const std::filesystem::path& path,
                                         TrainingStore::JournalReplay& replay) {
  auto back = std::make_unique<TrainingStore>(1e9, 10000);
  CHECK(back->load(path).empty());
  replay = back->replay_journal(path);
  return back;
}

}  // namespace

TEST_CASE("daemon: pairs journaled after the last save survive a power cut") {
  TempDir dir;
  const auto path = dir / "training.bin";
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 50);
  store.save(path);
  add_pairs(store, 50, 80);
  CHECK(store.append_journal(path) == 30);
  add_pairs(store, 80, 85);
  CHECK(store.append_journal(path) == 5);
  CHECK(store.append_journal(path) == 0);  // nothing new: no write
  add_pairs(store, 85, 90);                // never journaled: lost with the power

  TrainingStore::JournalReplay replay;
  const auto restored = restarted(path, replay);
  TrainingStore& back = *restored;
  CHECK(replay.recovered == 35);
  CHECK(replay.problem.empty());
  CHECK_FALSE(replay.stale);
  const auto got = back.snapshot();
  REQUIRE(got.size() == 85);
  CHECK(got.back().t == 1.7e9 + 84);
  CHECK(got.back().freq == 20.0 + 84);
  CHECK(back.new_samples() == 35);  // not in any fit yet

  SECTION("a save takes the journal's pairs and starts a fresh journal") {
    back.save(path);
    TrainingStore::JournalReplay again;
    CHECK(restarted(path, again)->size() == 85);
    CHECK(again.recovered == 0);
  }
  SECTION("a torn last record is dropped, and the journal is rewritten past it") {
    std::string journal = read_text(TrainingStore::journal_path(path));
    write_text(TrainingStore::journal_path(path), journal.substr(0, journal.size() - 9));
    TrainingStore::JournalReplay torn;
    const auto after_cut = restarted(path, torn);
    TrainingStore& cut = *after_cut;
    CHECK(torn.recovered == 34);
    CHECK(torn.problem.find("not a whole record") != std::string::npos);
    // Appending after the torn end would hide what follows it: the next write is a whole new journal.
    add_pairs(cut, 100, 102);
    CHECK(cut.append_journal(path) == 36);
    TrainingStore::JournalReplay after;
    CHECK(restarted(path, after)->size() == 50 + 36);
    CHECK(after.problem.empty());
  }
  SECTION("a flipped byte ends the replay at that record") {
    std::string journal = read_text(TrainingStore::journal_path(path));
    journal[journal.size() - 3 * 28 + 5] ^= 0x40;  // third record from the end
    write_text(TrainingStore::journal_path(path), journal);
    TrainingStore::JournalReplay flipped;
    CHECK(restarted(path, flipped)->size() == 50 + 32);
    // Said as what it is: whole records, the first of them failing its checksum.
    CHECK(flipped.problem == "record 33 fails its checksum; it and the 84 bytes from it on are dropped");
  }
  SECTION("a record that is not a number is skipped, and the records after it are kept") {
    // A pair no fit can use (a NaN speed) is not let into training from the journal either; its checksum
    // holds, so the records after it are sound.
    std::string journal = read_text(TrainingStore::journal_path(path));
    const std::size_t at = journal.size() - 3 * 28;  // third record from the end
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::memcpy(journal.data() + at + 8, &nan, sizeof nan);
    const std::uint32_t crc = crc32(std::string_view(journal).substr(at, 24));
    std::memcpy(journal.data() + at + 24, &crc, sizeof crc);
    write_text(TrainingStore::journal_path(path), journal);
    TrainingStore::JournalReplay implausible;
    const auto after = restarted(path, implausible);
    CHECK(implausible.recovered == 34);
    CHECK(implausible.skipped == 1);
    // Said as what it is: the record holds its checksum, not a pair.
    CHECK(implausible.problem ==
          "1 record(s) from record 33 on hold their checksum but no plausible pair (skipped)");
    const auto pairs = after->snapshot();
    CHECK(pairs.size() == 50 + 34);
    CHECK(std::all_of(pairs.begin(), pairs.end(), [](const Sample& s) { return std::isfinite(s.speed); }));
  }
}

// A disk that has no room for the whole store (a save writes all of it) may still take a journal's few
// records: the daemon's periodic save falls back to the journal then. A file size limit stands in for the
// full disk (it fails the same writes, and works for root, who runs these tests in CI).
TEST_CASE("daemon: pairs a failed save could not write are kept by the journal") {
  TempDir dir;
  const auto path = dir / "training.bin";
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 1000);
  store.save(path);
  add_pairs(store, 1000, 1040);
  REQUIRE(store.append_journal(path) == 40);
  add_pairs(store, 1040, 1060);
  {
    const FileSizeLimit limit(static_cast<rlim_t>(TrainingStore::file_bytes(1060) / 2));
    CHECK_THROWS_AS(store.save(path), std::system_error);
    CHECK(count_entries(dir.path()) == 2);  // the file and its journal as they were, no temp file left
    CHECK(store.unsaved());
    CHECK(store.unkept() == 20);  // what a power cut now would lose
    CHECK(store.append_journal(path) == 20);
    CHECK(store.unkept() == 0);
  }
  // Power lost before room came back: the old file and the journal hold every pair.
  TrainingStore::JournalReplay replay;
  CHECK(restarted(path, replay)->size() == 1060);
  CHECK(replay.recovered == 60);
  CHECK(replay.problem.empty());
  // With room again the next save takes them all and starts a fresh journal.
  store.save(path);
  TrainingStore::JournalReplay again;
  CHECK(restarted(path, again)->size() == 1060);
  CHECK(again.recovered == 0);
}

TEST_CASE("daemon: a journal older than the saved file is not replayed twice") {
  TempDir dir;
  const auto path = dir / "training.bin";
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 20);
  store.save(path);
  add_pairs(store, 20, 30);
  store.append_journal(path);
  const std::string old_journal = read_text(TrainingStore::journal_path(path));
  // Power lost between the save's rename and its fresh journal: the old journal names the old file.
  store.save(path);
  write_text(TrainingStore::journal_path(path), old_journal);
  TrainingStore::JournalReplay replay;
  CHECK(restarted(path, replay)->size() == 30);
  CHECK(replay.stale);
  CHECK(replay.recovered == 0);

  SECTION("nor one that is not a journal") {
    write_text(TrainingStore::journal_path(path), "garbage");
    TrainingStore::JournalReplay bad;
    CHECK(restarted(path, bad)->size() == 30);
    CHECK(bad.problem == "not a training journal (bad magic)");
  }
  SECTION("a first run that never saved is recovered from its journal alone") {
    TempDir fresh;
    TrainingStore first(1e9, 10000);
    add_pairs(first, 0, 12);
    CHECK(first.append_journal(fresh / "training.bin") == 12);
    TrainingStore::JournalReplay only;
    CHECK(restarted(fresh / "training.bin", only)->size() == 12);
    CHECK(only.recovered == 12);
  }
}

TEST_CASE("daemon: pairs journaled after a corrupt file was set aside are replayed at the next start") {
  TempDir dir;
  const auto path = dir / "training.bin";
  write_text(path, "GPTRAIN\ngarbage");
  TrainingStore store(1e9, 10000);
  CHECK_FALSE(store.load(path).empty());
  std::filesystem::rename(path, dir / "training.bin.corrupt");  // what the daemon does with it
  add_pairs(store, 0, 40);
  CHECK(store.append_journal(path) == 40);
  TrainingStore::JournalReplay replay;
  CHECK(restarted(path, replay)->size() == 40);
  CHECK(replay.recovered == 40);
}

// The journal names the saved file it follows. When that file is lost (deleted, or corrupt and set
// aside), the journal's pairs are in no other place: they were once dropped as belonging to another file.
TEST_CASE("daemon: pairs journaled after a save are kept when the saved file is lost") {
  TempDir dir;
  const auto path = dir / "training.bin";
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 50);
  store.save(path);
  add_pairs(store, 50, 67);
  REQUIRE(store.append_journal(path) == 17);
  SECTION("corrupt, set aside") {
    std::string bytes = read_text(path);
    bytes[bytes.size() / 2] ^= 0x01;
    write_text(path, bytes);
    TrainingStore back(1e9, 10000);
    CHECK_FALSE(back.load(path).empty());
    std::filesystem::rename(path, dir / "training.bin.corrupt");
    const TrainingStore::JournalReplay replay = back.replay_journal(path);
    CHECK(replay.recovered == 17);
    CHECK(back.size() == 17);
  }
  SECTION("deleted") {
    std::filesystem::remove(path);
    TrainingStore::JournalReplay replay;
    CHECK(restarted(path, replay)->size() == 17);
  }
}

TEST_CASE("daemon: pairs cleared by a reset do not come back from the journal") {
  // Every empty store's file is the same bytes: a journal written after one reset names the file a second
  // reset writes. The second reset's save removes the journal before it writes the file, so a power cut
  // between the two cannot pair them up.
  TempDir dir;
  const auto path = dir / "training.bin";
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 10);
  store.save(path);
  store.clear();
  store.save(path);
  const std::string empty_file = read_text(path);
  add_pairs(store, 10, 30);
  CHECK(store.append_journal(path) == 20);
  store.clear();
  // The save is cut short at its file write (a directory where the file goes makes the rename fail)...
  std::filesystem::remove(path);
  std::filesystem::create_directories(path / "x");
  CHECK_THROWS(store.save(path));
  // ...and the power goes with the new (empty, identical) file in place.
  std::filesystem::remove_all(path);
  write_text(path, empty_file);
  TrainingStore::JournalReplay replay;
  CHECK(restarted(path, replay)->size() == 0);
  CHECK(replay.recovered == 0);
}

TEST_CASE("daemon: training store rejects a torn or corrupt file") {
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 100; ++i)
    store.add({1.0 + i, 3.0, 40.0});
  const std::string good = store.serialize();
  TrainingStore back(1e9, 10000);
  REQUIRE(back.deserialize(good).empty());
  REQUIRE(back.size() == 100);

  SECTION("truncated") {
    CHECK_FALSE(back.deserialize(good.substr(0, good.size() - 30)).empty());
  }
  SECTION("a flipped byte") {
    std::string bad = good;
    bad[bad.size() / 2] ^= 0x10;
    CHECK(back.deserialize(bad) == "checksum mismatch");
  }
  SECTION("padded") {
    CHECK_FALSE(back.deserialize(good + std::string(24, '\0')).empty());
  }
  SECTION("not a store") {
    CHECK(back.deserialize(std::string(200, 'x')) == "not a training store (bad magic)");
  }
  SECTION("empty") {
    CHECK_FALSE(back.deserialize("").empty());
  }
  // A file another program wrote, or one corrupted before its checksum was taken: the checksum holds, and
  // what it says is still refused, so that the daemon sets the file aside instead of loading it.
  const auto with_checksum = [](std::string blob) {
    const std::uint32_t crc = crc32(std::string_view(blob).substr(0, blob.size() - 4));
    std::memcpy(blob.data() + blob.size() - 4, &crc, sizeof crc);
    return blob;
  };
  SECTION("a record count so large that its size in bytes wraps round to the file's") {
    // 2^61 + 100 records of 24 bytes come to 2400 bytes modulo 2^64, what the file holds: taken at its
    // word, the count has the loader read far past the end of the file.
    std::string bad = good;
    const std::uint64_t count = (std::uint64_t{1} << 61) + 100;
    std::memcpy(bad.data() + 16, &count, sizeof count);
    CHECK(back.deserialize(with_checksum(bad)).rfind("truncated or padded", 0) == 0);
  }
  CHECK(back.size() == 0);
}

TEST_CASE("daemon: a record that is no pair though the file's checksum holds is skipped, the rest kept") {
  // One bad pair cost the whole store (2,401 pairs set aside): the checksum shows every record is where
  // it belongs, so only the bad one goes.
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 100; ++i)
    store.add({1.0 + i, 3.0, 40.0 + i});
  std::string bad = store.serialize();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(bad.data() + 24 + 50 * 24 + 16, &nan, sizeof nan);  // record 50's frequency
  const double negative = -5.0;
  std::memcpy(bad.data() + 24 + 70 * 24 + 8, &negative, sizeof negative);  // record 70's speed
  const std::uint32_t crc = crc32(std::string_view(bad).substr(0, bad.size() - 4));
  std::memcpy(bad.data() + bad.size() - 4, &crc, sizeof crc);
  TrainingStore back(1e9, 10000);
  CHECK(back.deserialize(bad).empty());
  CHECK(back.skipped() == 2);
  const auto pairs = back.snapshot();
  REQUIRE(pairs.size() == 98);
  CHECK(std::all_of(pairs.begin(), pairs.end(), [](const Sample& s) { return std::isfinite(s.freq); }));
  CHECK(pairs[49].freq == 40.0 + 49);
  CHECK(pairs[50].freq == 40.0 + 51);
  CHECK(back.deserialize(store.serialize()).empty());
  CHECK(back.skipped() == 0);
}

TEST_CASE("daemon: what is read of the state directory is bounded") {
  TempDir dir;
  // A valid model whose extra makes it longer than kMaxModelBytes is refused unparsed.
  GearModel model = three_gears();
  model.extra["notes"] = std::string(gearpulse::daemon::kMaxModelBytes, 'x');
  save_model_file(dir / "model.json", model);
  const ModelLoad big = load_model_file(dir / "model.json");
  CHECK_FALSE(big.model);
  CHECK(big.error.find("longer than 1048576 bytes") != std::string::npos);
  model.extra["notes"] = std::string(1000, 'x');
  save_model_file(dir / "model.json", model);
  CHECK(load_model_file(dir / "model.json").model);
  // A FIFO in the store's place: refused at once, not waited on.
  REQUIRE(::mkfifo((dir / "training.bin").c_str(), 0600) == 0);
  TrainingStore store(1e9, 10000);
  CHECK_THROWS_AS(store.load(dir / "training.bin"), gearpulse::FileRefused);
}

TEST_CASE("daemon: a corrupt model file is reported and ignored") {
  TempDir dir;
  write_text(dir / "model.json", "{\"version\":1,\"gears\":[{\"theta\":0.1},{\"theta\":0.05}]");
  const ModelLoad torn = load_model_file(dir / "model.json");
  CHECK(torn.model == nullptr);
  CHECK_FALSE(torn.error.empty());
  write_text(dir / "model.json", "{\"version\":1,\"gears\":[{\"theta\":0.1},{\"theta\":0.05}]}");
  const ModelLoad unordered = load_model_file(dir / "model.json");
  CHECK(unordered.model == nullptr);
  CHECK_FALSE(unordered.error.empty());
  const ModelLoad absent = load_model_file(dir / "none.json");
  CHECK(absent.model == nullptr);
  CHECK(absent.error.empty());
}

TEST_CASE("daemon: model file round-trips in the format of gearpulse fit") {
  TempDir dir;
  save_model_file(dir / "model.json", three_gears());
  const ModelLoad back = load_model_file(dir / "model.json");
  REQUIRE(back.model);
  REQUIRE(back.model->gears.size() == 3);
  CHECK(back.model->gears[1].theta == Approx(0.09));
  const auto json = nlohmann::json::parse(read_text(dir / "model.json"));
  CHECK(json["version"] == 1);
  CHECK(json["gears"][2]["stderr"].get<double>() == Approx(0.002));
}

TEST_CASE("daemon: retrainer swaps in and saves a fitted model") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 20; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::size_t seen = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample> s, std::stop_token) {
                        seen = s.size();
                        return three_gears();
                      },
                      {});
  const auto wall = [] {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  };
  const double before = wall();
  CHECK(retrainer.retrain_now());
  // Status says when the model was last retrained (gearpulsectl's "last retrain").
  CHECK(retrainer.status().runs == 1);
  CHECK(retrainer.status().last_run_wall >= std::floor(before));
  CHECK(retrainer.status().last_run_wall <= wall() + 1.0);
  CHECK(seen == 20);
  REQUIRE(model.trained());
  CHECK(model.get()->gears.size() == 3);
  const ModelLoad saved = load_model_file(dir / "model.json");
  REQUIRE(saved.model != nullptr);
  CHECK(store.new_samples() == 0);
  CHECK(retrainer.status().accepted == 1);
  // The newest pair it saw is kept with the model: at the next start, pairs after it are new.
  CHECK(saved.model->extra.value(std::string(kTrainedUntil), -1.0) == 19.0);
  add_pairs(store, 20, 26);
  TrainingStore next_start(1e9, 10000);
  REQUIRE(next_start.deserialize(store.serialize()).empty());
  CHECK(next_start.new_samples() == 0);
  next_start.set_new_after(saved.model->extra.value(std::string(kTrainedUntil), -1.0));
  CHECK(next_start.new_samples() == 6);
}

TEST_CASE("daemon: a retrain that found the GPS speeds late against the engine says gps.latency is off") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 20; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  double lag = 0.0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        GearModel m = three_gears();
                        m.extra["speed_lag"] = lag;
                        return m;
                      },
                      {});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency") == std::string::npos);
  lag = 0.05;  // within what the search resolves at 1 Hz: not worth a word
  store.add({19.5, 10.0, 100.0});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency") == std::string::npos);
  lag = 0.375;  // the fit paired each engine reading with the speed stamped 0.375 s after it
  store.add({20.0, 10.0, 100.0});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency may be 0.38 s too short") != std::string::npos);
  CHECK(retrainer.status().last_result.find("describe the engine 0.38 s before their stamps") !=
        std::string::npos);
  lag = -0.5;
  store.add({21.0, 10.0, 100.0});
  CHECK(retrainer.retrain_now());
  CHECK(retrainer.status().last_result.find("gps.latency may be 0.50 s too long") != std::string::npos);
  CHECK(retrainer.status().last_result.find("describe the engine 0.50 s after their stamps") !=
        std::string::npos);
}

TEST_CASE(
    "daemon: pairs stamped with a gps.latency shorter than the receiver's are reported by the retrain") {
  // As the pipeline pairs them: a fix received at rx is stamped rx - gps.latency and paired with the engine
  // frequency at that stamp. The receiver reports 0.5 s after the instant it describes, the config says
  // 0: each pair holds the engine at t and the speed of t - 0.5 s.
  const sim::Vehicle car = sim::vehicle_preset("hatch-5");
  sim::ObservationOptions ten_hz;
  ten_hz.period = 0.1;
  const auto observed = sim::simulate_observations(car, sim::DrivingStyle::kUrban, 2400.0, 1, 7, ten_hz);
  constexpr std::size_t kLateRows = 5;  // 0.5 s
  TempDir dir;
  TrainingStore store(1e9, 100000);
  for (std::size_t k = kLateRows; k < observed.size(); ++k)
    store.add({observed[k].truth.t, observed[k - kLateRows].speed, observed[k].freq});
  ModelHolder model;
  Retrainer retrainer(store, model, dir / "model.json",
                      [](std::span<const Sample> s, std::stop_token) { return fit_gear_model(s, {}).model; },
                      {});
  CHECK(retrainer.retrain_now());
  INFO(retrainer.status().last_result);
  const std::string& said = retrainer.status().last_result;
  const auto at = said.find("gps.latency may be ");
  REQUIRE(at != std::string::npos);
  CHECK(std::stod(said.substr(at + 19)) == Approx(0.5).margin(0.03));
  CHECK(said.find("s too short") != std::string::npos);
}

TEST_CASE("daemon: retrainer fits at start when the store holds enough pairs its model has not seen") {
  // Trips shorter than the retrain interval: the pairs gathered over several of them are learned from at
  // the next start, not never.
  TempDir dir;
  TrainingStore store(1e9, 10000);
  add_pairs(store, 0, 50);
  ModelHolder model;
  model.set(std::make_shared<const GearModel>(three_gears()));
  std::atomic<int> fits{0};
  const auto fitter = [&](std::span<const Sample>, std::stop_token) {
    ++fits;
    return three_gears();
  };
  const Retrainer::Settings settings{std::chrono::duration<double>(3600.0), 30};
  SECTION("enough new pairs") {
    store.set_new_after(pair_time(10));  // 39 newer than the model's fit
    Retrainer retrainer(store, model, dir / "model.json", fitter, settings);
    retrainer.start();
    for (int i = 0; i < 500 && fits.load() == 0; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    retrainer.stop();
    CHECK(fits.load() == 1);
  }
  SECTION("too few: it waits for the interval") {
    store.set_new_after(pair_time(25));  // 24 newer
    Retrainer retrainer(store, model, dir / "model.json", fitter, settings);
    retrainer.start();
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    retrainer.stop();
    CHECK(fits.load() == 0);
  }
}

TEST_CASE("daemon: an empty or failed fit never replaces a good model") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  const auto good = std::make_shared<const GearModel>(three_gears());
  model.set(good);
  int calls = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) -> GearModel {
                        if (++calls == 1) {
                          GearModel none;
                          none.reason = "no discrete ladder";
                          return none;
                        }
                        throw std::runtime_error("optimizer diverged");
                      },
                      {});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == good);
  CHECK(retrainer.status().last_result.find("no discrete ladder") != std::string::npos);
  store.add({2.0, 10.0, 100.0});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == good);
  CHECK(retrainer.status().last_result.find("optimizer diverged") != std::string::npos);
  // The pairs a failed fit saw count as tried: the retrainer waits for new ones instead of failing on
  // the same pairs at every interval.
  CHECK(store.new_samples() == 0);
  CHECK_FALSE(std::filesystem::exists(dir / "model.json"));
}

TEST_CASE("daemon: a retrain with no training pairs yet says so and runs no fit") {
  // A `retrain` right after a reset: the user reads that there is nothing to learn from, not a fit on no
  // pairs that "found no gear ladder".
  TempDir dir;
  TrainingStore store(1e9, 10000);
  ModelHolder model;
  std::atomic<int> fits{0};
  Retrainer retrainer(store, model, dir / "model.json", counting_fitter(fits), {});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(fits.load() == 0);
  CHECK_FALSE(model.trained());
  CHECK(retrainer.status().last_result == "no training samples yet");
  CHECK(retrainer.status().runs == 1);
  CHECK(retrainer.status().accepted == 0);
}

TEST_CASE("daemon: a fit that again finds no gear ladder is noted, not warned about at every retrain") {
  // An automatic answers "no ladder" at every retrain interval; the log at 2 a.m. should say so once.
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  bool ladder = false;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) -> GearModel {
                        if (ladder) return three_gears();
                        GearModel none;
                        none.reason = "no discrete ladder";
                        return none;
                      },
                      {});
  gearpulse::test::LogLines log;
  const auto levels_of_ladder_lines = [&] { return log.levels("no gear ladder"); };
  retrainer.retrain_now();
  retrainer.retrain_now();
  retrainer.retrain_now();
  const auto first = levels_of_ladder_lines();
  ladder = true;
  retrainer.retrain_now();
  ladder = false;
  retrainer.retrain_now();
  const auto after = levels_of_ladder_lines();
  using L = spdlog::level::level_enum;
  CHECK(first == std::vector<L>{L::warn, L::info, L::info});
  // Once a fit found a ladder, losing it again is news.
  CHECK(after == std::vector<L>{L::warn, L::info, L::info, L::warn});
  CHECK(retrainer.status().last_result.find("no discrete ladder") != std::string::npos);
}

TEST_CASE("daemon: a fit begun before a model reset is discarded, not installed over the reset") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  model.set(std::make_shared<const GearModel>(three_gears()));
  int fits = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        if (++fits == 1) {
                          // reset-model arrives while the first fit runs (as the control thread does it)
                          const auto lock = model.lock_writes();
                          model.set(nullptr);
                        }
                        return three_gears();
                      },
                      {});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == nullptr);
  CHECK_FALSE(std::filesystem::exists(dir / "model.json"));
  CHECK(retrainer.status().last_result.find("discarded") != std::string::npos);
  // The next fit, begun after the reset, is installed.
  CHECK(retrainer.retrain_now());
  CHECK(model.trained());
}

TEST_CASE("daemon: a removed file stays removed (durable remove), and removing an absent one is no error") {
  TempDir dir;
  const auto path = dir / "model.json";
  gearpulse::write_file_atomic(path, "{}");
  REQUIRE(std::filesystem::exists(path));
  gearpulse::remove_file_durable(path);
  CHECK_FALSE(std::filesystem::exists(path));
  CHECK_NOTHROW(gearpulse::remove_file_durable(path));
  std::filesystem::create_directory(dir / "sub");
  CHECK_THROWS_AS(gearpulse::remove_file_durable(dir / "sub"), std::system_error);  // not a file
}

TEST_CASE("daemon: retrainer thread fits when asked and stops promptly") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 5; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::atomic<int> fits{0};
  Retrainer retrainer(store, model, dir / "model.json", counting_fitter(fits),
                      {std::chrono::duration<double>(3600.0), 1000});
  retrainer.start();
  retrainer.request();
  wait_for_a_fit(fits);
  retrainer.stop();
  CHECK(fits.load() == 1);
  CHECK(model.trained());
}

TEST_CASE("daemon: stopping the retrainer cancels a fit under way and keeps its pairs new") {
  // A fit under SCHED_IDLE on a CPU others keep busy can take minutes; a SIGTERM must not wait for it.
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 5; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::atomic<bool> fitting{false};
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token stop) -> GearModel {
                        fitting = true;
                        // A long fit: its passes over the pairs end when a stop is asked for.
                        const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
                        while (std::chrono::steady_clock::now() < give_up) {
                          if (stop.stop_requested()) throw FitCancelled();
                          std::this_thread::sleep_for(std::chrono::milliseconds(5));
                        }
                        return three_gears();
                      },
                      {std::chrono::duration<double>(3600.0), 1000});
  retrainer.start();
  retrainer.request();
  for (int i = 0; i < 500 && !fitting; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  REQUIRE(fitting);
  const auto t0 = std::chrono::steady_clock::now();
  retrainer.stop();
  CHECK(std::chrono::steady_clock::now() - t0 < std::chrono::seconds(5));
  CHECK_FALSE(model.trained());
  CHECK(retrainer.status().last_result.find("cancelled") != std::string::npos);
  CHECK_FALSE(retrainer.status().busy);
  CHECK(store.new_samples() == 5);  // the next start fits them
}

TEST_CASE("daemon: the estimator's fit ends with FitCancelled once a stop is requested") {
  std::vector<Sample> pairs;
  for (int i = 0; i < 600; ++i)  // two gears' lines
    pairs.push_back({double(i), 5.0 + 0.01 * i, (i % 2 ? 40.0 : 25.0) + 0.02 * i});
  std::stop_source stop;
  stop.request_stop();
  CHECK_THROWS_AS(make_estimator_fitter()(pairs, stop.get_token()), FitCancelled);
  FitOptions paper;
  paper.ratios = {1.4, 1.5};
  paper.stop = stop.get_token();
  CHECK_THROWS_AS(fit_gear_model(pairs, paper), FitCancelled);
  CHECK_NOTHROW(make_estimator_fitter()(pairs, {}));
}

TEST_CASE("daemon: a retrain interval shortened while the retrainer waits applies at once") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  ModelHolder model;
  std::atomic<int> fits{0};
  Retrainer retrainer(store, model, dir / "model.json", counting_fitter(fits),
                      {std::chrono::duration<double>(3600.0), 5});
  retrainer.start();  // nothing to learn from at start: it waits an hour
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  for (int i = 0; i < 10; ++i)
    store.add({double(i), 10.0, 100.0});
  // As a reload sets it: the wait under way ends at the new interval, not the old one.
  Retrainer::Settings shorter = retrainer.settings();
  shorter.interval = std::chrono::duration<double>(0.2);
  retrainer.set_settings(shorter);
  wait_for_a_fit(fits);
  retrainer.stop();
  CHECK(fits.load() >= 1);
}

TEST_CASE("daemon: the fit runs in a thread of its own at low priority, the rest at the caller's") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  for (int i = 0; i < 5; ++i)
    store.add({double(i), 10.0, 100.0});
  ModelHolder model;
  std::thread::id fit_thread;
  int fit_nice = 0;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        fit_thread = std::this_thread::get_id();
                        errno = 0;
                        fit_nice = ::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)));
                        return three_gears();
                      },
                      {std::chrono::duration<double>(600.0), 1});
  errno = 0;
  const int caller_nice = ::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)));
  CHECK(retrainer.retrain_now());
  CHECK(fit_thread != std::this_thread::get_id());
  CHECK(fit_nice == 19);
  // The caller (who takes the store's copy and installs and saves the model) keeps its priority.
  CHECK(::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid))) == caller_nice);
  // A fit that throws is reported as it was on the caller's thread.
  Retrainer failing(
      store, model, dir / "model.json",
      [](std::span<const Sample>, std::stop_token) -> GearModel { throw std::runtime_error("no memory"); },
      {std::chrono::duration<double>(600.0), 1});
  CHECK_FALSE(failing.retrain_now());
  CHECK(failing.status().last_result.find("no memory") != std::string::npos);
  // Nor may a fit that throws something other than a std::exception end the retrainer's thread (and with
  // it the daemon): it is a failed fit, the model kept.
  Retrainer odd(store, model, dir / "model.json",
                [](std::span<const Sample>, std::stop_token) -> GearModel { throw 42; },
                {std::chrono::duration<double>(600.0), 1});
  CHECK_FALSE(odd.retrain_now());
  CHECK(odd.status().last_result.find("fit failed") != std::string::npos);
  CHECK_FALSE(odd.status().busy);
}

TEST_CASE("daemon: a fit on few samples does not replace a model learned on many") {
  TempDir dir;
  TrainingStore store(1e9, 10000);
  store.add({1.0, 10.0, 100.0});
  ModelHolder model;
  GearModel big = three_gears();
  big.samples = 50'000;
  const auto good = std::make_shared<const GearModel>(big);
  model.set(good);
  std::size_t fitted_samples = 100;
  Retrainer retrainer(store, model, dir / "model.json",
                      [&](std::span<const Sample>, std::stop_token) {
                        GearModel m = three_gears();
                        m.samples = fitted_samples;
                        return m;
                      },
                      {std::chrono::duration<double>(600.0), 1, 3600});
  CHECK_FALSE(retrainer.retrain_now());
  CHECK(model.get() == good);
  fitted_samples = 3600;
  CHECK(retrainer.retrain_now());
  CHECK(model.get()->samples == 3600);
  // Without a model any ladder is better than none.
  model.set(nullptr);
  fitted_samples = 10;
  CHECK(retrainer.retrain_now());
  CHECK(model.get()->samples == 10);
}
