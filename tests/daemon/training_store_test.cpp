// The training store: bounded by age (driving time) and count, its file round-tripped and checked, and
// the journal that keeps the pairs gathered since the last save through a power cut.
#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <string>
#include <string_view>
#include <system_error>

#include "daemon/training_store.hpp"
#include "tests/daemon/persistence_fixtures.hpp"
#include "tests/test_util.hpp"

using namespace gearpulse;
using namespace gearpulse::daemon;
using gearpulse::test::add_pairs;
using gearpulse::test::count_entries;
using gearpulse::test::FileSizeLimit;
using gearpulse::test::pair_time;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::write_text;

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

TEST_CASE("daemon: a store and journal beyond model.max_samples are read in pieces, the newest kept") {
  // 10,000 pairs make a file of 240 KB and 5,000 a journal of 140 KB: both read in 64 KiB pieces, the
  // file's second and the journal's third of which start inside a record.
  TempDir dir;
  const auto path = dir / "training.bin";
  TrainingStore store(1e9, 20000);
  add_pairs(store, 0, 10000);
  store.save(path);
  add_pairs(store, 10000, 15000);
  REQUIRE(store.append_journal(path) == 5000);

  SECTION("a store of a larger bound reads both whole") {
    TrainingStore back(1e9, 20000);
    REQUIRE(back.load(path).empty());
    const auto replay = back.replay_journal(path);
    CHECK(replay.recovered == 5000);
    CHECK(replay.problem.empty());
    const auto a = store.snapshot();
    const auto b = back.snapshot();
    REQUIRE(a.size() == b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      CHECK(a[i].t == b[i].t);
      CHECK(a[i].freq == b[i].freq);
    }
  }
  SECTION("a store bounded to 1,000 pairs keeps the newest 1,000 of each") {
    TrainingStore back(1e9, 1000);
    REQUIRE(back.load(path).empty());
    REQUIRE(back.size() == 1000);
    CHECK(back.snapshot().front().t == pair_time(9000));
    CHECK(back.snapshot().back().t == pair_time(9999));
    const auto replay = back.replay_journal(path);
    CHECK(replay.recovered == 5000);
    REQUIRE(back.size() == 1000);
    CHECK(back.snapshot().front().t == pair_time(14000));
    CHECK(back.snapshot().back().t == pair_time(14999));
    CHECK(back.new_samples() == 1000);
  }
}

namespace {

// VmRSS or VmHWM of this process, in KiB (-1 when /proc does not say).
long status_kib(const std::string& field) {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind(field + ":", 0) == 0) return std::stol(line.substr(field.size() + 1));
  return -1;
}

}  // namespace

TEST_CASE(
    "daemon: loading a store saved under a larger model.max_samples takes no more memory than its "
    "bound") {
  // A million pairs (24 MB) saved by a child process, so this one never held them; loaded into a store of
  // 1,000 pairs, the peak resident memory grows by far less than the file (read whole, it grew by the
  // file and the pairs, 46 MB).
  TempDir dir;
  const auto path = dir / "training.bin";
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    TrainingStore big(1e9, 1'000'000);
    for (int i = 0; i < 1'000'000; ++i)
      big.add({pair_time(i), 10.0, 50.0});
    big.save(path);
    std::_Exit(0);
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  REQUIRE(WIFEXITED(status));
  REQUIRE(WEXITSTATUS(status) == 0);
  {
    // Resets the peak to what is resident now (Linux 4.0 on).
    std::ofstream reset("/proc/self/clear_refs");
    reset << "5" << std::flush;
    if (!reset) GEARPULSE_SKIP_TEST("cannot reset the peak resident memory (/proc/self/clear_refs)");
  }
  const long before = status_kib("VmRSS");
  REQUIRE(before > 0);
  TrainingStore back(1e9, 1000);
  REQUIRE(back.load(path).empty());
  CHECK(back.size() == 1000);
  CHECK(back.snapshot().back().t == pair_time(999'999));
  const long grown = status_kib("VmHWM") - before;
  INFO("peak resident memory grew by " << grown << " KiB");
  CHECK(grown < 8 * 1024);
}
