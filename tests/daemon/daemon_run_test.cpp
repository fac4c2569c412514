// Runs the built gearpulsed as a process: no gpsd, no sound card, output "none".
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/ptrace.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include <ctime>

#include <nlohmann/json.hpp>

#include "core/gear_model.hpp"
#include "daemon/control_server.hpp"
#include "daemon/model_store.hpp"
#include "daemon/training_store.hpp"
#include "daemon/watchdog.hpp"
#include "tests/drivers/alsa_fifo.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/vehicle_sim.hpp"

using gearpulse::test::LineClient;
using gearpulse::test::Process;
using gearpulse::test::read_text;
using gearpulse::test::TempDir;
using gearpulse::test::write_text;
using nlohmann::json;

namespace {

const std::string kDaemon = GEARPULSE_BINARY_DIR "/daemon/gearpulsed";

std::string config_for(const TempDir& dir, const std::string& extra_output = "") {
  return "[audio]\ndevice = \"gearpulse_test_no_such_pcm\"\n"
         "[gps]\nhost = \"127.0.0.1\"\nport = " +
         std::to_string(gearpulse::test::free_port()) +
         "\n"
         "[output]\nkind = \"none\"\n" +
         extra_output + "[model]\nstate_dir = \"" + (dir / "state").string() +
         "\"\n"
         "[control]\nsocket = \"" +
         (dir / "ctl.sock").string() + "\"\n[log]\nlevel = \"debug\"\n";
}

// `text` with its first `from` replaced by `to` (a config_for() with one setting changed).
std::string with(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  REQUIRE(at != std::string::npos);
  return text.replace(at, from.size(), to);
}

// config_for() with its output on a PTY whose link is `link`.
std::string pty_config_for(const TempDir& dir, const std::filesystem::path& link) {
  return with(config_for(dir), "kind = \"none\"\n", "kind = \"pty\"\npath = \"" + link.string() + "\"\n");
}

// Status once the daemon answers, or null after the timeout.
json wait_for_status(const TempDir& dir, Process& daemon, int timeout_ms = 15'000) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline && daemon.running()) {
    LineClient c((dir / "ctl.sock").string());
    if (c.connected() && c.send_all("{\"v\":1,\"cmd\":\"status\"}\n"))
      if (const auto line = c.read_line()) return json::parse(*line);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return nullptr;
}

// Starts the daemon on dir's gearpulse.toml, waits for its first status, stops it with SIGTERM (it must
// exit 0) and returns that status (null if it never answered).
json status_of_one_run(const TempDir& dir) {
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  json status = wait_for_status(dir, daemon);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  return status;
}

json ask(const TempDir& dir, const std::string& request) {
  LineClient c((dir / "ctl.sock").string());
  REQUIRE(c.connected());
  REQUIRE(c.send_all(request + "\n"));
  const auto line = c.read_line();
  REQUIRE(line.has_value());
  return json::parse(*line);
}

const char* kModel = R"({"version":1,"gears":[{"theta":0.043,"weight":0.2,"stderr":0.0002},
{"theta":0.072,"weight":0.3,"stderr":0.0003},{"theta":0.106,"weight":0.5,"stderr":0.0004}],
"sigma_speed":0.3,"sigma_freq":0.6,"samples":1234,"log_likelihood":-10.5})";

// Saves in `dir`/state a training store of a 40-minute bmw-520i drive (seed `seed`) that ended at
// `end_wall_s`, and a config that retrains at start on 1000 new pairs; returns the store's size.
std::size_t store_a_drive(const TempDir& dir, std::uint64_t seed, double end_wall_s) {
  std::filesystem::create_directories(dir / "state");
  const auto obs = gearpulse::sim::simulate_observations(
      gearpulse::sim::vehicle_preset("bmw-520i"), gearpulse::sim::DrivingStyle::kMixed, 2400.0, 1, seed);
  gearpulse::daemon::TrainingStore store(1e9, 1'000'000);
  for (const auto& s : gearpulse::sim::to_samples(obs))
    store.add({end_wall_s - 2400.0 + s.t, s.speed, s.freq});
  store.save(dir / "state/training.bin");
  // config_for already has a [model] table: the retrain keys go into it.
  std::string text = config_for(dir);
  text.replace(text.find("[model]\n"), 8, "[model]\nmin_new_samples = 1000\nretrain_interval = 3600\n");
  write_text(dir / "gearpulse.toml", text);
  return store.size();
}

// Status once `done` holds for it (or the daemon answers no more, or a minute has passed).
template <class Done>
json status_once(const TempDir& dir, Process& daemon, Done done) {
  json status;
  for (int i = 0; i < 600; ++i) {
    status = wait_for_status(dir, daemon);
    if (!status.is_object() || done(status)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return status;
}

// Waits up to `timeout` for the daemon's log (dir/log.txt) to say `text`.
bool log_says(const TempDir& dir, std::string_view text, std::chrono::milliseconds timeout) {
  return gearpulse::test::wait_for([&] { return read_text(dir / "log.txt").find(text) != std::string::npos; },
                                   timeout);
}

}  // namespace

TEST_CASE("daemon: runs with output none and no gpsd or ALSA and answers status") {
  TempDir dir;
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["v"] == 1);
  CHECK(status["ok"] == true);
  for (const char* key :
       {"speed", "source", "gear", "pulses", "gears", "uptime", "gps", "audio", "tracker", "model"})
    CHECK(status.contains(key));
  CHECK(status["gears"].is_array());
  CHECK(status["gears"].empty());
  CHECK(status["model"]["state"] == "learning");
  CHECK(status["gps"]["state"] != "fix");
  CHECK(status["pulses"] == 0);
  // A new install: no gear known, the learning schedule waiting for a first gear.
  CHECK(status["model"]["known_gears"] == json::array());
  CHECK(status["model"]["learning"]["young"] == true);
  CHECK(status["model"]["learning"]["moving_time"] == 0.0);
  CHECK(status["model"]["learning"]["cluster_pairs"] == 0);
  CHECK(status["model"]["learning"]["first_fit_pairs"] == 40);

  // reset-model needs an explicit confirmation.
  const json refused = ask(dir, R"({"v":1,"cmd":"reset-model"})");
  CHECK(refused["ok"] == false);
  CHECK(refused["error"].get<std::string>().find("confirm") != std::string::npos);
  CHECK(ask(dir, R"({"v":1,"cmd":"reset-model","confirm":false})")["ok"] == false);
  // A keep_samples that is not a boolean is said so, before anything is forgotten.
  const json odd = ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true,"keep_samples":"yes"})");
  CHECK(odd["ok"] == false);
  CHECK(odd["error"].get<std::string>().find("keep_samples") != std::string::npos);
  CHECK(ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true})")["ok"] == true);
  CHECK(ask(dir, R"({"v":1,"cmd":"nonsense"})")["ok"] == false);
  // The command is named whole, escaped, even with a NUL inside (it ended the message there).
  CHECK(ask(dir, R"({"v":1,"cmd":"st\u0000atus\n'"})")["error"] ==
        R"(unknown command 'st\u0000atus\u000a\'' (status, gears, retrain, reset-model))");
  CHECK(ask(dir, R"({"v":1,"cmd":"gears"})")["model_state"] == "learning");
  CHECK(ask(dir, R"({"v":1,"cmd":"retrain"})")["ok"] == true);

  // Still up a moment later, with missing devices retried rather than fatal.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  CHECK(daemon.running());
  CHECK(wait_for_status(dir, daemon)["ok"] == true);

  daemon.signal(SIGHUP);
  CHECK(wait_for_status(dir, daemon)["ok"] == true);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  // The absent gpsd is said at once (later failures at most once a minute).
  CHECK(read_text(dir / "log.txt").find("reconnecting with backoff") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir / "ctl.sock"));
  CHECK(std::filesystem::exists(dir / "state/training.bin"));
}

TEST_CASE("daemon: reset-model says so when the training pairs cannot be cleared from disk") {
  TempDir dir;
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon).is_object());
  // A store file that can be neither replaced nor removed: a directory with something in it.
  std::filesystem::create_directories(dir / "state/training.bin/keep");
  const json reply = ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true})");
  INFO(reply.dump());
  CHECK(reply["ok"] == false);
  CHECK(reply["error"].get<std::string>().find("cannot be cleared") != std::string::npos);
  std::filesystem::remove_all(dir / "state/training.bin");
  CHECK(ask(dir, R"({"v":1,"cmd":"reset-model","confirm":true})")["ok"] == true);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a PTY output in a directory that does not exist yet is made there") {
  TempDir dir;
  const std::filesystem::path link = dir / "run" / "sub" / "pulse";
  write_text(dir / "gearpulse.toml", pty_config_for(dir, link));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(status.is_object());
  CHECK(status["output"]["error"] == "");
  CHECK(std::filesystem::is_symlink(link));
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: an output that will not open is retried until it does, without a restart") {
  TempDir dir;
  const std::filesystem::path link = dir / "pulse";
  write_text(link, "a file where the link should go\n");  // the PTY output refuses to replace it
  write_text(dir / "gearpulse.toml", pty_config_for(dir, link));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json failing = wait_for_status(dir, daemon);
  INFO(read_text(dir / "log.txt"));
  REQUIRE(failing.is_object());
  CHECK(failing["output"]["state"] == "error");
  CHECK(failing["output"]["error"].get<std::string>().find("not a symlink") != std::string::npos);
  std::filesystem::remove(link);
  json status;
  for (int i = 0; i < 100 && !std::filesystem::is_symlink(link); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  CHECK(std::filesystem::is_symlink(link));
  status = wait_for_status(dir, daemon);
  // Open, but no process has the device open: said in status and once in the log.
  CHECK(status["output"]["state"] == "no-reader");
  CHECK(status["output"]["unheard"] == 0);  // no GPS: no pulses yet
  CHECK(status["output"]["error"] == "");
  CHECK(read_text(dir / "log.txt").find("opened on a retry") != std::string::npos);
  CHECK(log_says(dir, "no process has " + link.string() + " open", std::chrono::seconds(5)));
  {
    const gearpulse::UniqueFd reader(::open(link.c_str(), O_RDONLY | O_NOCTTY | O_NONBLOCK));
    REQUIRE(reader);
    CHECK(log_says(dir, "a reader has " + link.string() + " open", std::chrono::seconds(5)));
    CHECK(wait_for_status(dir, daemon)["output"]["state"] == "ok");
  }
  CHECK(gearpulse::test::wait_for(
      [&] { return wait_for_status(dir, daemon)["output"]["state"] == "no-reader"; },
      std::chrono::seconds(5)));
  const std::string log = read_text(dir / "log.txt");
  std::size_t said = 0;
  for (std::size_t at = 0; (at = log.find("no process has", at)) != std::string::npos; ++at)
    ++said;
  CHECK(said == 1);  // the reader's return and second leave within a minute: not said again
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: SIGTERM saves what is learned before it waits for a capture stuck in the device") {
  TempDir dir;
  // A capture whose read never returns: the file plugin reads a FIFO whose writer is there but silent.
  const std::filesystem::path fifo = gearpulse::test::make_paced_pcm(dir, "stuck");
  struct Writer {  // closed however the test ends, so a failed check cannot leave the daemon stuck
    int fd;
    ~Writer() {
      if (fd >= 0) ::close(fd);
    }
  } writer{::open(fifo.c_str(), O_RDWR | O_CLOEXEC)};
  REQUIRE(writer.fd >= 0);
  write_text(dir / "gearpulse.toml", with(config_for(dir), "gearpulse_test_no_such_pcm", "stuck"));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  // The capture is open (so its thread is in, or about to be in, its read).
  json status;
  for (int i = 0; i < 300 && !(status.is_object() && status["audio"]["state"] == "running"); ++i) {
    status = wait_for_status(dir, daemon);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  REQUIRE(status["audio"]["state"] == "running");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  daemon.signal(SIGTERM);
  // The store is saved while the daemon still waits for the capture thread.
  const bool saved = log_says(dir, "(shutdown)", std::chrono::seconds(5));
  INFO(read_text(dir / "log.txt"));
  CHECK(saved);
  CHECK(std::filesystem::exists(dir / "state/training.bin"));
  CHECK(log_says(dir, "has not returned from the device", std::chrono::seconds(15)));
  CHECK(daemon.running());
  ::close(writer.fd);  // the read returns (end of file): the daemon can finish
  writer.fd = -1;
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: a second gearpulsed on the same state directory exits before it touches it") {
  TempDir dir;
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process first({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "first.txt");
  REQUIRE(wait_for_status(dir, first).is_object());
  // As if the first were in the middle of a save: its temp file must survive the second's start.
  write_text(dir / "state/training.bin.tmp.AbC123", "half a save");
  // The second has a socket of its own, so only the state directory is shared.
  write_text(dir / "second.toml",
             with(config_for(dir), (dir / "ctl.sock").string(), (dir / "other.sock").string()));
  Process second({kDaemon, "--config", (dir / "second.toml").string()}, dir / "second.txt");
  const auto rc = second.wait();
  REQUIRE(rc.has_value());
  CHECK(*rc == 1);
  CHECK(read_text(dir / "second.txt").find("another gearpulsed keeps its state in") != std::string::npos);
  CHECK(read_text(dir / "state/training.bin.tmp.AbC123") == "half a save");
  CHECK(first.running());
  first.signal(SIGTERM);
  CHECK(first.wait() == 0);
}

TEST_CASE("daemon: a malformed config is refused with file and line before anything opens") {
  TempDir dir;
  write_text(dir / "bad.toml",
             "[audio]\nrate = 48000\n\n[output]\nkind = \"none\"\npulses_per_km = 0\n[control]\nsocket = \"" +
                 (dir / "ctl.sock").string() + "\"\n");
  Process daemon({kDaemon, "--config", (dir / "bad.toml").string()}, dir / "log.txt");
  const auto rc = daemon.wait();
  REQUIRE(rc.has_value());
  CHECK(*rc != 0);
  const std::string log = read_text(dir / "log.txt");
  CHECK(log.find((dir / "bad.toml").string() + ":6: output.pulses_per_km:") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir / "ctl.sock"));

  Process check({kDaemon, "--config", (dir / "bad.toml").string(), "--check-config"}, dir / "log2.txt");
  CHECK(check.wait() == 2);
  write_text(dir / "good.toml", config_for(dir));
  Process good({kDaemon, "--config", (dir / "good.toml").string(), "--check-config"}, dir / "log3.txt");
  CHECK(good.wait() == 0);
}

TEST_CASE("daemon: a config that never ends or never opens is refused with exit 2, naming it") {
  TempDir dir;
  const std::string fifo = (dir / "fifo.toml").string();
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  int n = 0;
  for (const std::string& path : {std::string("/dev/zero"), fifo}) {
    CAPTURE(path);
    const auto log = dir / ("log" + std::to_string(++n) + ".txt");
    Process check({kDaemon, "--config", path, "--check-config"}, log);
    CHECK(check.wait(10'000) == 2);
    CHECK(read_text(log).find("gearpulsed: " + path + ": cannot read config file: not a regular file") !=
          std::string::npos);
  }
}

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

TEST_CASE("daemon: a PTY link whose directory cannot be made says why") {
  TempDir dir;
  write_text(dir / "run", "a file where a directory should be\n");
  write_text(dir / "gearpulse.toml", pty_config_for(dir, dir / "run" / "pulse"));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  const json status = wait_for_status(dir, daemon);
  REQUIRE(status.is_object());
  CHECK(status["output"]["state"] == "error");
  const std::string error = status["output"]["error"].get<std::string>();
  CHECK(error.find("cannot create the directory") != std::string::npos);
  CHECK(error.find("Not a directory") != std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
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
  CHECK(read_text(dir / "log.txt").find("a full training store") != std::string::npos);
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
  CHECK(read_text(dir / "log.txt").find("(the file is left where it is: Permission denied)") !=
        std::string::npos);
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
  CHECK(log_says(dir, "will not survive a restart", std::chrono::seconds(5)));
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
  CHECK(read_text(dir / "log.txt").find("stored pairs are new to it") != std::string::npos);
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
  CHECK(read_text(dir / "log.txt").find("1200 of the " + std::to_string(before + 1200) + " stored pairs") !=
        std::string::npos);
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
    CHECK(read_text(dir / "log.txt").find("10 pairs recovered from") != std::string::npos);
    // Consolidated at once: a second power cut cannot lose them either.
    daemon.signal(SIGKILL);
    CHECK(daemon.wait() == 128 + SIGKILL);
  }
  gearpulse::daemon::TrainingStore back(1e9, 1000);
  REQUIRE(back.load(path).empty());
  CHECK(back.size() == 30);
  CHECK(back.replay_journal(path).recovered == 0);
}

TEST_CASE("daemon: tells systemd ready and stopping and feeds the watchdog") {
  TempDir dir;
  const std::string notify_path = (dir / "notify").string();
  const int sock = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, notify_path.c_str(), sizeof addr.sun_path - 1);
  REQUIRE(::bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt",
                 {.env = {"NOTIFY_SOCKET=" + notify_path, "WATCHDOG_USEC=600000"}});
  std::string all;
  const auto receive_until = [&](const std::string& what) {
    for (int i = 0; i < 200 && all.find(what) == std::string::npos; ++i) {
      pollfd pfd{sock, POLLIN, 0};
      if (::poll(&pfd, 1, 100) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::recv(sock, buf, sizeof buf, 0);
      if (n > 0) all.append(buf, static_cast<std::size_t>(n)).append("\n");
    }
    return all.find(what) != std::string::npos;
  };
  CHECK(receive_until("READY=1"));
  CHECK(all.find("STATUS=") != std::string::npos);
  CHECK(receive_until("WATCHDOG=1"));
  daemon.signal(SIGTERM);
  CHECK(receive_until("STOPPING=1"));
  CHECK(daemon.wait() == 0);
  ::close(sock);
}

TEST_CASE("daemon: a thread that stops turning withholds WATCHDOG=1 until it turns again") {
  // Every thread but the main one is stopped (ptrace, a thread at a time: the main thread runs on and
  // judges the others' heartbeats), as a thread stuck in a driver would be.
  if (::geteuid() != 0) {
    std::puts("GEARPULSE_SKIP: needs root to stop the daemon's threads with ptrace");
    return;
  }
  TempDir dir;
  const std::string notify_path = (dir / "notify").string();
  const int sock = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, notify_path.c_str(), sizeof addr.sun_path - 1);
  REQUIRE(::bind(sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt",
                 {.env = {"NOTIFY_SOCKET=" + notify_path, "WATCHDOG_USEC=2000000"}});
  // The WATCHDOG=1 messages that arrive within `ms`.
  const auto pings_within = [&](int ms) {
    int pings = 0;
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (std::chrono::steady_clock::now() < until) {
      pollfd pfd{sock, POLLIN, 0};
      if (::poll(&pfd, 1, 50) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::recv(sock, buf, sizeof buf, 0);
      if (n > 0 && std::string_view(buf, static_cast<std::size_t>(n)).find("WATCHDOG=1") != std::string::npos)
        ++pings;
    }
    return pings;
  };
  REQUIRE(wait_for_status(dir, daemon).is_object());
  CHECK(pings_within(2'000) >= 2);
  std::vector<pid_t> stopped;
  for (const auto& task :
       std::filesystem::directory_iterator("/proc/" + std::to_string(daemon.pid()) + "/task")) {
    const pid_t tid = std::stoi(task.path().filename().string());
    if (tid == daemon.pid()) continue;
    if (::ptrace(PTRACE_SEIZE, tid, nullptr, nullptr) != 0) continue;
    if (::ptrace(PTRACE_INTERRUPT, tid, nullptr, nullptr) == 0 && ::waitpid(tid, nullptr, __WALL) == tid)
      stopped.push_back(tid);
  }
  REQUIRE(stopped.size() >= 3);  // the tracker, GPS and pulse threads at least
  // Within the stall limit (5 s) and a tick the pings stop, and stay stopped: longer than the unit's
  // WatchdogSec (10 s) systemd kills the daemon and, by Restart=on-failure, starts it again.
  (void)pings_within(static_cast<int>(gearpulse::daemon::kStallNs / 1'000'000) + 1'500);
  CHECK(pings_within(3'000) == 0);
  CHECK(daemon.running());
  for (const pid_t tid : stopped)
    ::ptrace(PTRACE_DETACH, tid, nullptr, nullptr);
  CHECK(pings_within(3'000) >= 2);
  CHECK(log_says(dir, "thread(s) not responding: ", std::chrono::seconds(5)));
  const std::string unit = read_text(GEARPULSE_SOURCE_DIR "/systemd/gearpulsed.service.in");
  CHECK(unit.find("\nWatchdogSec=") != std::string::npos);
  CHECK(unit.find("\nRestart=on-failure\n") != std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
  ::close(sock);
}

TEST_CASE("control: gearpulsectl prints status tables and JSON and fails clearly without a daemon") {
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  {
    Process absent({ctl, "--socket", sock, "status"}, dir / "absent.txt");
    const auto rc = absent.wait();
    REQUIRE(rc.has_value());
    CHECK(*rc != 0);
    CHECK(read_text(dir / "absent.txt").find("gearpulsed is not running") != std::string::npos);
    Process unknown({ctl, "--socket", sock, "--json", "frobnicate"}, dir / "unknown.txt");
    CHECK(unknown.wait() == 2);
    CHECK(read_text(dir / "unknown.txt").find("unknown command 'frobnicate'") != std::string::npos);
  }
  write_text(dir / "gearpulse.toml", config_for(dir));
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon).is_object());

  Process table({ctl, "--socket", sock, "status"}, dir / "table.txt");
  CHECK(table.wait() == 0);
  const std::string text = read_text(dir / "table.txt");
  CHECK(text.find("source") != std::string::npos);
  CHECK(text.find("model        learning") != std::string::npos);

  Process full({ctl, "--socket", sock, "status"}, "/dev/full");  // a reply that cannot be written
  CHECK(full.wait() == 2);

  Process raw({ctl, "--socket", sock, "status", "--json"}, dir / "raw.txt");
  CHECK(raw.wait() == 0);
  const json parsed = json::parse(read_text(dir / "raw.txt"));
  CHECK(parsed["ok"] == true);
  CHECK(parsed.contains("pulses"));

  Process refuse({ctl, "--socket", sock, "reset-model"}, dir / "refuse.txt");
  CHECK(refuse.wait() == 2);
  CHECK(read_text(dir / "refuse.txt").find("--confirm") != std::string::npos);
  Process reset({ctl, "--socket", sock, "reset-model", "--confirm"}, dir / "reset.txt");
  CHECK(reset.wait() == 0);
  Process gears({ctl, "--socket", sock, "gears"}, dir / "gears.txt");
  CHECK(gears.wait() == 0);
  Process retrain({ctl, "--socket", sock, "retrain", "--json"}, dir / "retrain.txt");
  CHECK(retrain.wait() == 0);
  CHECK(json::parse(read_text(dir / "retrain.txt"))["queued"] == true);

  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("control: gearpulsectl reports a daemon's refusal, not the broken pipe it leaves") {
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  // The server refuses another user's connection when the daemon's own user (root here) holds every slot.
  const std::string as_nobody = "/usr/bin/setpriv --reuid=65534 --regid=65534 --clear-groups ";
  if (::geteuid() != 0 || !std::filesystem::exists("/usr/bin/setpriv") ||
      std::system((as_nobody + "test -x " + ctl).c_str()) != 0) {
    std::puts("GEARPULSE_SKIP: needs root and a gearpulsectl that user nobody may run");
    return;
  }
  std::filesystem::permissions(dir.path(), std::filesystem::perms::all);
  const std::string sock = (dir / "ctl.sock").string();
  gearpulse::daemon::ControlServer server(
      sock,
      [](const json&) {
        return json{{"x", 1}};
      },
      gearpulse::daemon::ControlLimits{.max_clients = 1});
  server.start();
  std::filesystem::permissions(sock, std::filesystem::perms::all);
  LineClient holder(sock);  // takes the one slot
  REQUIRE(holder.send_all("{\"cmd\":\"status\"}\n"));
  REQUIRE(holder.read_line().has_value());
  // The server writes its reason and closes without reading: most runs' request then meets a closed
  // socket (EPIPE), and the reason waiting in it is what the user must see.
  for (int i = 0; i < 10; ++i) {
    const auto out = dir / ("busy" + std::to_string(i) + ".txt");
    Process p({"/usr/bin/setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", ctl, "--socket", sock,
               "status"},
              out);
    CHECK(p.wait() == 1);
    CHECK(read_text(out) == "gearpulsectl: too many clients\n");
  }
  // A path that is no socket is named as such, not as a daemon that is not running.
  write_text(dir / "plain", "x");
  Process plain({ctl, "--socket", (dir / "plain").string(), "status"}, dir / "plain.txt");
  CHECK(plain.wait() == 3);
  CHECK(read_text(dir / "plain.txt").find("is not a socket") != std::string::npos);
}

namespace {
// A listening Unix socket at `path` that is not gearpulsed, for gearpulsectl to talk to.
int listen_unix(const std::string& path) {
  const int listener = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  REQUIRE(listener >= 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
  REQUIRE(::bind(listener, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0);
  REQUIRE(::listen(listener, 4) == 0);
  return listener;
}
}  // namespace

TEST_CASE("control: gearpulsectl reports a reply of the wrong shape instead of aborting") {
  // Something else on the socket (or a broken daemon) answers valid JSON that is not a status.
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  const int listener = listen_unix(sock);
  // The last two: a status whose "gps" is no object (found after the speed line was printed, which then
  // stood above the error), and a reply that never ends (read without bound before).
  const std::vector<std::string> replies = {R"([1,2])",
                                            R"({"ok":"yes"})",
                                            R"({"ok":false,"error":5})",
                                            R"({"ok":true,"gears":[1]})",
                                            R"({"ok":true,"speed":1.5,"gps":5})",
                                            std::string(2 << 20, ' ')};
  std::thread server([&] {
    for (const std::string& reply : replies) {
      const int c = ::accept(listener, nullptr, nullptr);
      if (c < 0) return;
      char buf[512];
      (void)!::read(c, buf, sizeof buf);
      const std::string line = reply + "\n";
      (void)!::send(c, line.data(), line.size(), MSG_NOSIGNAL);  // the client may stop reading first
      ::close(c);
    }
  });
  for (const std::string& reply : replies) {
    INFO(reply.substr(0, 80));
    Process p({ctl, "--socket", sock, "status"}, dir / "out.txt");
    const auto rc = p.wait();
    REQUIRE(rc.has_value());
    CHECK(*rc == 1);
    const std::string out = read_text(dir / "out.txt");
    CHECK(out.rfind("gearpulsectl: ", 0) == 0);
    CHECK(out.find("speed ") == std::string::npos);  // nothing of a status printed above the error
  }
  server.join();
  ::close(listener);
}

TEST_CASE("control: gearpulsectl refuses a reply nested too deep instead of printing it") {
  // Printed with --json (recursively), a reply nested 100,000 deep would overflow the stack or grow to
  // gigabytes of indentation first.
  TempDir dir;
  const std::string ctl = GEARPULSE_BINARY_DIR "/tools/gearpulsectl";
  const std::string sock = (dir / "ctl.sock").string();
  const int listener = listen_unix(sock);
  std::thread server([&] {
    const int c = ::accept(listener, nullptr, nullptr);
    if (c < 0) return;
    char buf[512];
    (void)!::read(c, buf, sizeof buf);
    const std::string line =
        R"({"ok":true,"x":)" + std::string(100000, '[') + std::string(100000, ']') + "}\n";
    (void)!::send(c, line.data(), line.size(), MSG_NOSIGNAL);
    ::close(c);
  });
  Process p({ctl, "--socket", sock, "status", "--json"}, dir / "out.txt");
  const auto rc = p.wait();
  server.join();
  ::close(listener);
  REQUIRE(rc.has_value());
  CHECK(*rc == 1);
  CHECK(read_text(dir / "out.txt") == "gearpulsectl: gearpulsed sent a reply nested deeper than 64 levels\n");
}

TEST_CASE("daemon: a reload whose store limits drop stored pairs says how many") {
  TempDir dir;
  std::filesystem::create_directories(dir / "state");
  gearpulse::daemon::TrainingStore store(1e9, 1000);
  const double now = static_cast<double>(std::time(nullptr));
  for (int i = 0; i < 300; ++i)
    store.add({now - 600.0 + i, 10.0, 50.0});
  store.save(dir / "state/training.bin");
  const std::string base = config_for(dir);
  write_text(dir / "gearpulse.toml", base);
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon)["training_samples"] == 300);
  write_text(dir / "gearpulse.toml", with(base, "[model]\n", "[model]\nmax_samples = 100\n"));
  daemon.signal(SIGHUP);
  const bool said = log_says(dir, "drop 200 of its 300 pairs", std::chrono::seconds(5));
  INFO(read_text(dir / "log.txt"));
  CHECK(said);
  CHECK(wait_for_status(dir, daemon)["training_samples"] == 100);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}

TEST_CASE("daemon: SIGHUP applies what it can and names what needs a restart") {
  TempDir dir;
  const std::string base = config_for(dir);
  write_text(dir / "gearpulse.toml", base);
  Process daemon({kDaemon, "--config", (dir / "gearpulse.toml").string()}, dir / "log.txt");
  REQUIRE(wait_for_status(dir, daemon).is_object());
  const auto wait_log = [&](const std::string& what) {
    for (int i = 0; i < 200; ++i) {
      if (read_text(dir / "log.txt").find(what) != std::string::npos) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }
    return false;
  };
  // A broken file on reload is refused; the daemon keeps its running configuration.
  write_text(dir / "gearpulse.toml", base + "[bogus]\n");
  daemon.signal(SIGHUP);
  CHECK(wait_log("keeping the running configuration"));
  const json refused = wait_for_status(dir, daemon);
  CHECK(refused["ok"] == true);
  CHECK(refused["config"]["reload_error"].get<std::string>().find("bogus") != std::string::npos);
  // A file that is not there: the reason is given.
  std::filesystem::rename(dir / "gearpulse.toml", dir / "moved.toml");
  daemon.signal(SIGHUP);
  CHECK(wait_log("cannot open config file: No such file or directory"));
  std::filesystem::rename(dir / "moved.toml", dir / "gearpulse.toml");

  std::string changed = base;
  changed.replace(changed.find("gearpulse_test_no_such_pcm"), 26, "gearpulse_test_other_pcm__");
  changed.replace(changed.find("[model]\n"), 8, "[model]\nmin_new_samples = 7\n");
  write_text(dir / "gearpulse.toml", changed);
  daemon.signal(SIGHUP);
  CHECK(wait_log("reload: [audio] changed; this takes effect only after a restart"));
  CHECK(wait_log("reload: applied"));
  const json applied = wait_for_status(dir, daemon);
  CHECK(applied["ok"] == true);
  CHECK(applied["config"]["reload_error"] == "");
  CHECK(applied["config"]["restart_pending"] == json::array({"[audio]"}));
  daemon.signal(SIGTERM);
  CHECK(daemon.wait() == 0);
}
