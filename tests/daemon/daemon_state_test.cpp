// The built gearpulsed on its state directory: the model and training store loaded, kept and saved
// across stops and kill -9, files that are corrupt or unreadable set aside, a directory without room or
// that it may not write in said, and a model learned at start from the pairs it finds.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <limits>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "core/gear_model.hpp"
#include "daemon/model_store.hpp"
#include "daemon/training_store.hpp"
#include "tests/daemon/daemon_process.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::test::config_for;
using gearpulse::test::kDaemon;
using gearpulse::test::kModel;
using gearpulse::test::log_says;
using gearpulse::test::Process;
using gearpulse::test::read_text;
using gearpulse::test::status_of_one_run;
using gearpulse::test::status_once;
using gearpulse::test::store_a_drive;
using gearpulse::test::TempDir;
using gearpulse::test::wait_for_status;
using gearpulse::test::with;
using gearpulse::test::write_text;
using nlohmann::json;

TEST_CASE("daemon: model.json is loaded at start and survives kill -9") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  write_text(dir / "state/model.json", kModel);
  write_text(dir / "gearpulse.toml", config_for(dir));
  {
    Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
    const json status = wait_for_status(dir, daemon);
    REQUIRE(status.is_object());
    CHECK(status["model"]["state"] == "trained");
    REQUIRE(status["gears"].size() == 3);
    CHECK(status["gears"][1]["theta"].get<double>() == Approx(0.072));
    CHECK(status["gears"][1]["stderr"].get<double>() == Approx(0.0003));
    daemon.signal(SIGKILL);
    CHECK(daemon.wait() == 128 + SIGKILL);
  }
  // The socket file of the killed daemon is stale; the new one takes over.
  Process again({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, again);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["gears"].size() == 3);
  again.signal(SIGTERM);
  CHECK(again.wait() == 0);
}

TEST_CASE(
    "daemon: a model unchanged since it was loaded is not rewritten at stop, however its file is spaced") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  const auto path = dir / "state/model.json";
  gearpulse::daemon::save_model_file(path, gearpulse::parse_model(kModel));
  write_text(dir / "gearpulse.toml", config_for(dir));
  const auto inode = [&] {
    struct stat st {};
    REQUIRE(::stat(path.c_str(), &st) == 0);
    return st.st_ino;
  };
  const auto before = inode();
  REQUIRE(status_of_one_run(dir).is_object());
  CHECK(inode() == before);  // an atomic save would have renamed a new file over it
  // The file as a person wrote it (other spacing, no final newline), or as an earlier version did: the
  // same model, so not rewritten either (it once was, and on read-only media every stop said it failed).
  for (const std::string& text :
       {std::string(kModel), gearpulse::serialize_model(gearpulse::parse_model(kModel)) + "\n"}) {
    write_text(path, text);
    const auto written = inode();
    REQUIRE(status_of_one_run(dir).is_object());
    CHECK(inode() == written);
    CHECK(read_text(path) == text);
  }
}

TEST_CASE("daemon: a training store the file already holds is not rewritten at stop") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  const auto path = dir / "state/training.bin";
  gearpulse::daemon::TrainingStore store(1e9, 1000);
  const double now = static_cast<double>(std::time(nullptr));
  for (int i = 0; i < 30; ++i)
    store.add({now - 60.0 + i, 10.0, 50.0});
  store.save(path);
  write_text(dir / "gearpulse.toml", config_for(dir));
  struct stat before {};
  REQUIRE(::stat(path.c_str(), &before) == 0);
  REQUIRE(status_of_one_run(dir)["training_samples"] == 30);
  struct stat after {};
  REQUIRE(::stat(path.c_str(), &after) == 0);
  CHECK(after.st_ino == before.st_ino);  // a save would have renamed a new file over it
}

TEST_CASE("daemon: a state_dir without room for the training store is said at start") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  // A 64 kB file system: needs the right to mount one (root in a container that allows it).
  if (std::system(
          ("mount -t tmpfs -o size=64k tmpfs '" + (dir / "state").string() + "' 2>/dev/null").c_str()) != 0) {
    GEARPULSE_SKIP_TEST("cannot mount a small tmpfs here");
  }
  struct Unmount {
    std::string at;
    ~Unmount() { (void)!std::system(("umount '" + at + "'").c_str()); }
  } unmount{(dir / "state").string()};
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  const std::string problems = status["model"]["problems"].dump();
  CHECK(problems.find("MB free in") != std::string::npos);
  CHECK(log_says(dir, "a full training store", std::chrono::seconds(15)));
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a corrupt model and training store are logged, set aside and shown in status") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  const std::string torn_model = std::string(kModel).substr(0, 60);
  write_text(dir / "state/model.json", torn_model);
  write_text(dir / "state/training.bin", "GPTRAIN\ngarbage");
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  REQUIRE(status.is_object());
  CHECK(status["model"]["state"] == "learning");
  CHECK(status["training_samples"] == 0);
  // Status says what was thrown away, not only that the daemon is learning.
  const json problems = status["model"]["problems"];
  REQUIRE(problems.size() == 2);
  CHECK(problems[0].get<std::string>().find("model.json ignored") != std::string::npos);
  CHECK(problems[1].get<std::string>().find("training.bin discarded") != std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  const std::string log = read_text(dir / "log.txt");
  CHECK(log.find("model: ignoring") != std::string::npos);
  CHECK(log.find("training: discarding") != std::string::npos);
  // The files are kept as they were, beside what the daemon saved since.
  CHECK(read_text(dir / "state/model.json.corrupt") == torn_model);
  CHECK(read_text(dir / "state/training.bin.corrupt") == "GPTRAIN\ngarbage");
  CHECK(std::filesystem::exists(dir / "state/training.bin"));
}

TEST_CASE("daemon: a training store with one pair that is no pair keeps the rest and says so in status") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  gearpulse::daemon::TrainingStore store(1e9, 1'000'000);
  for (int i = 0; i < 2401; ++i)
    store.add({1.7e9 + i, 10.0, 100.0});
  std::string bytes = store.serialize();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(bytes.data() + 24 + 1200 * 24 + 8, &nan, sizeof nan);  // record 1200's speed
  const std::uint32_t crc = gearpulse::daemon::crc32(std::string_view(bytes).substr(0, bytes.size() - 4));
  std::memcpy(bytes.data() + bytes.size() - 4, &crc, sizeof crc);
  write_text(dir / "state/training.bin", bytes);
  write_text(dir / "state/training.bin.journal", "not a journal");  // said in status too
  // And a model.json over the bound: refused unparsed, set aside.
  write_text(dir / "state/model.json", std::string(kModel).substr(0, std::string(kModel).size() - 1) +
                                           ",\"extra\":{\"x\":\"" + std::string(2 << 20, 'x') + "\"}}");
  write_text(dir / "gearpulse.toml", config_for(dir));
  const json status = status_of_one_run(dir);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["training_samples"] == 2400);
  const std::string problems = status["model"]["problems"].dump();
  CHECK(problems.find("training.bin: 1 record(s) hold their checksum but no plausible pair; skipped") !=
        std::string::npos);
  CHECK(problems.find("longer than 1048576 bytes") != std::string::npos);
  CHECK(problems.find("training.bin.journal: not a training journal (bad magic)") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir / "state/training.bin.corrupt"));
  CHECK(std::filesystem::exists(dir / "state/model.json.corrupt"));
}

// A second corruption keeps the first one's evidence; a model.json that cannot be read at all (here a
// directory; for a daemon user, a file another user installed with mode 0600) is set aside too, so the
// daemon's saves never go over it.
TEST_CASE("daemon: a model.json set aside takes a name not yet taken, and an unreadable one is set aside") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state/model.json");  // cannot be read as a file
  write_text(dir / "state/model.json.corrupt", "the first corruption\n");
  write_text(dir / "gearpulse.toml", config_for(dir));
  REQUIRE(status_of_one_run(dir).is_object());
  INFO(read_text(dir / "log.txt"));
  CHECK(read_text(dir / "state/model.json.corrupt") == "the first corruption\n");
  CHECK(std::filesystem::is_directory(dir / "state/model.json.corrupt.1"));
  CHECK_FALSE(std::filesystem::exists(dir / "state/model.json"));
}

// A training.bin that cannot be read (a read error, or a file another user installed with mode 0600; here a
// directory) is set aside as a corrupt one is: the store's saves replace the file whole, and the few pairs
// of this run would otherwise take the place of the history it holds.
TEST_CASE("daemon: an unreadable training.bin is set aside, not saved over") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state/training.bin/history");  // cannot be read as a file
  write_text(dir / "gearpulse.toml", config_for(dir));
  REQUIRE(status_of_one_run(dir).is_object());
  const std::string log = read_text(dir / "log.txt");
  INFO(log);
  CHECK(log.find("training: cannot read") != std::string::npos);
  CHECK(log.find("kept as " + (dir / "state/training.bin.corrupt").string()) != std::string::npos);
  CHECK(std::filesystem::is_directory(dir / "state/training.bin.corrupt/history"));
}

// Copies are kept up to a hundred (NAME.corrupt, then .corrupt.1 to .corrupt.99): the hundredth
// corruption still has its evidence kept, under the last name.
TEST_CASE("daemon: a corrupt model.json with 99 copies set aside already is kept as the hundredth") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  const std::string torn_model = std::string(kModel).substr(0, 60);
  write_text(dir / "state/model.json", torn_model);
  write_text(dir / "state/model.json.corrupt", "corruption 0\n");
  for (int n = 1; n <= 98; ++n)
    write_text(dir / ("state/model.json.corrupt." + std::to_string(n)),
               "corruption " + std::to_string(n) + "\n");
  write_text(dir / "gearpulse.toml", config_for(dir));
  REQUIRE(status_of_one_run(dir).is_object());
  INFO(read_text(dir / "log.txt"));
  CHECK(read_text(dir / "state/model.json.corrupt.99") == torn_model);
  CHECK(read_text(dir / "state/model.json.corrupt.98") == "corruption 98\n");
  CHECK(read_text(dir / "log.txt").find("kept as " + (dir / "state/model.json.corrupt.99").string()) !=
        std::string::npos);
}

// A user installs a model with `gearpulse fit --out STATE/model.json` while the daemon runs: the daemon
// does not save its own over it at stop (it once did, silently), and loads it at the next start.
TEST_CASE(
    "daemon: a model.json installed while it runs is not overwritten, and is loaded at the next start") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  const auto path = dir / "state/model.json";
  gearpulse::daemon::save_model_file(path, gearpulse::parse_model(kModel));
  write_text(dir / "gearpulse.toml", config_for(dir));
  const char* installed = R"({"version":1,"gears":[{"theta":0.05,"weight":0.5,"stderr":0.0002},
{"theta":0.09,"weight":0.5,"stderr":0.0003}],"sigma_speed":0.3,"sigma_freq":0.6,"samples":999,
"log_likelihood":-1.5})";
  {
    Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
    REQUIRE(wait_for_status(dir, daemon)["gears"].size() == 3);
    gearpulse::daemon::save_model_file(path, gearpulse::parse_model(installed));
    daemon.signal(SIGTERM);
    CHECK(daemon.wait() == 0);
  }
  INFO(read_text(dir / "log.txt"));
  CHECK(gearpulse::daemon::model_file_holds(path, gearpulse::parse_model(installed)));
  CHECK(read_text(dir / "log.txt").find("was replaced while gearpulsed ran") != std::string::npos);
  Process again({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log2.txt");
  CHECK(wait_for_status(dir, again)["gears"].size() == 2);
  again.signal(SIGTERM);
  CHECK(again.wait() == 0);
}

// A state_dir the daemon's user may not search (root's, mode 0700): every lookup in it fails with EACCES.
// Looking for a free name to set model.json aside spun forever there, at full CPU, deaf to SIGTERM.
TEST_CASE("daemon: a state directory it may not search is said at start, and the daemon runs") {
  TempDir dir;
  const std::string as_nobody = "/usr/bin/setpriv --reuid=65534 --regid=65534 --clear-groups ";
  if (::geteuid() != 0 || !std::filesystem::exists("/usr/bin/setpriv") ||
      std::system((as_nobody + "test -x " + kDaemon).c_str()) != 0) {
    GEARPULSE_SKIP_TEST("needs root and a gearpulsed that user nobody may run");
  }
  std::filesystem::permissions(dir.path(), std::filesystem::perms::all);  // nobody makes its socket here
  std::filesystem::create_directories(dir / "state");
  std::filesystem::permissions(dir / "state", std::filesystem::perms::owner_all);
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({"/usr/bin/setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", kDaemon, "--config",
                  (dir / "gearpulse.toml").string()},
                 dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["model"]["problems"].size() >= 1);
  // The reason model.json stays where it is, not a search for a free name that found none.
  CHECK(log_says(dir, "(the file is left where it is: Permission denied)", std::chrono::seconds(15)));
  CHECK(read_text(dir / "log.txt").find("copies are set aside already") == std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a state directory it cannot write in is said at start and in status") {
  TempDir dir;
  // A state_dir under a regular file: it cannot be made, so nothing can be saved there (a directory
  // without write permission would do, but not for root, who runs these tests in CI).
  write_text(dir / "blocker", "not a directory\n");
  write_text(dir / "gearpulse.toml",
             with(config_for(dir), (dir / "state").string(), (dir / "blocker" / "state").string()));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  REQUIRE(status["model"]["problems"].size() >= 1);
  CHECK(status["model"]["problems"][0].get<std::string>().find("cannot create") != std::string::npos);
  CHECK(status["model"]["problems"].size() == 1);  // not also a model.json "ignored" under a file
  // The log goes through its own thread: the line may come a moment after status shows the problem.
  CHECK(log_says(dir, "will not survive a restart", std::chrono::seconds(15)));
  // The plain status shows it as it shows a GPS or audio problem.
  Process table(
      {GEARPULSE_BINARY_DIR "/tools/gearpulsectl", "--socket", (dir / "ctl.sock").string(), "status"},
      dir / "table.txt");
  CHECK(table.wait() == 0);
  CHECK(read_text(dir / "table.txt").find("! model: cannot create") != std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

// A model installed with `gearpulse fit --out` carries no extra.trained_until: it has seen none of the
// stored pairs, so they count as new at start (they once counted as none, and a car driven only on short
// trips never retrained).
TEST_CASE("daemon: stored pairs are new to a model it did not fit, and it learns from them at start") {
  TempDir dir;
  const std::size_t pairs = store_a_drive(dir, 22, static_cast<double>(std::time(nullptr)));
  REQUIRE(pairs > 1234);  // more than the installed model was fitted on
  write_text(dir / "state/model.json", kModel);
  const std::size_t gears = gearpulse::sim::vehicle_preset("bmw-520i").theta.size();
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = status_once(dir, daemon, [&](const json& s) { return s["gears"].size() == gears; });
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["gears"].size() == gears);
  CHECK(log_says(dir, "stored pairs are new to it", std::chrono::seconds(15)));
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: learns a model from a restored training store and saves it") {
  TempDir dir;
  const auto vehicle = gearpulse::sim::vehicle_preset("bmw-520i");
  // Driven, then parked for 60 h (more than store_hours): time parked does not age what was learned.
  const double parked_since = static_cast<double>(std::time(nullptr)) - 60.0 * 3600.0;
  const std::size_t pairs = store_a_drive(dir, 21, parked_since);
  REQUIRE(pairs > 1000);
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  json status = status_once(dir, daemon, [](const json& s) { return s["model"]["state"] == "trained"; });
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  REQUIRE(status["model"]["state"] == "trained");
  REQUIRE(status["gears"].size() == vehicle.theta.size());
  for (std::size_t i = 0; i < vehicle.theta.size(); ++i)
    CHECK(status["gears"][i]["theta"].get<double>() == Approx(vehicle.theta[i]).epsilon(0.02));
  CHECK(status["training_samples"].get<std::size_t>() == pairs);
  // Learned from a drive longer than the learning schedule: settled, every gear known from pairs of its own.
  CHECK(status["model"]["learning"]["young"] == false);
  CHECK(status["model"]["learning"]["next_refit"].is_null());
  REQUIRE(status["model"]["known_gears"].size() == vehicle.theta.size());
  for (const json& g : status["model"]["known_gears"]) {
    CHECK(g["pairs"].get<std::size_t>() > 0);
    CHECK(g["kept"] == false);
  }
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  // Written atomically in the format of `gearpulse fit --out`, and loaded again.
  const auto loaded = gearpulse::daemon::load_model_file(dir / "state/model.json");
  REQUIRE(loaded.model);
  CHECK(loaded.model->gears.size() == vehicle.theta.size());

  // Later trips, each shorter than the retrain interval, add pairs the model has not seen: the next start
  // counts them as new and learns from them at once, even when the car PC's clock was years behind while
  // they were made (no RTC battery, not yet set from GPS).
  gearpulse::daemon::TrainingStore later(1e9, 1'000'000);
  REQUIRE(later.load(dir / "state/training.bin").empty());
  const std::size_t before = later.size();
  for (int i = 0; i < 1200; ++i)
    later.add({parked_since - 3 * 365 * 86400.0 + i, 10.0, 60.0});
  later.save(dir / "state/training.bin");
  Process again({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json restarted =
      status_once(dir, again, [](const json& s) { return s["model"]["retrain_runs"].get<int>() >= 1; });
  INFO(read_text(dir / "log.txt"));
  REQUIRE(restarted.is_object());
  CHECK(restarted["model"]["retrain_runs"].get<int>() >= 1);
  CHECK(log_says(dir, "1200 of the " + std::to_string(before + 1200) + " stored pairs",
                 std::chrono::seconds(15)));
  again.signal(SIGTERM);
  CHECK(again.wait() == 0);
}

TEST_CASE("daemon: pairs journaled before a power cut are restored at start and saved with the store") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  const auto path = dir / "state/training.bin";
  gearpulse::daemon::TrainingStore store(1e9, 1000);
  const double now = static_cast<double>(std::time(nullptr));
  for (int i = 0; i < 30; ++i) {
    store.add({now - 60.0 + i, 10.0, 50.0});
    if (i == 19) store.save(path);
  }
  REQUIRE(store.append_journal(path) == 10);
  write_text(dir / "gearpulse.toml", config_for(dir));
  {
    Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
    const json status = wait_for_status(dir, daemon);
    INFO(read_text(dir / "log.txt"));
    REQUIRE(status.is_object());
    CHECK(status["training_samples"] == 30);
    CHECK(log_says(dir, "10 pairs recovered from", std::chrono::seconds(15)));
    // Consolidated at once: a second power cut cannot lose them either.
    daemon.signal(SIGKILL);
    CHECK(daemon.wait() == 128 + SIGKILL);
  }
  gearpulse::daemon::TrainingStore back(1e9, 1000);
  REQUIRE(back.load(path).empty());
  CHECK(back.size() == 30);
  CHECK(back.replay_journal(path).recovered == 0);
}
