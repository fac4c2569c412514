// The daemon's state files: written atomically (whole at any crash), stale temp files cleaned, a file
// removed durably, what is read of the state directory bounded, the model file. The training store is in
// training_store_test.cpp, the retrainer in retrainer_test.cpp.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <random>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/atomic_file.hpp"
#include "daemon/model_store.hpp"
#include "daemon/training_store.hpp"
#include "tests/daemon/persistence_fixtures.hpp"
#include "tests/test_util.hpp"

using namespace gearpulse;
using namespace gearpulse::daemon;
using gearpulse::test::count_entries;
using gearpulse::test::FileSizeLimit;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::three_gears;
using gearpulse::test::write_text;

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
