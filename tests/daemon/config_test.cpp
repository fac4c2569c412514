#include <catch2/catch.hpp>

#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>

#include "daemon/config.hpp"
#include "tests/test_util.hpp"

using gearpulse::daemon::Config;
using gearpulse::daemon::ConfigError;
using gearpulse::daemon::OutputKind;
using gearpulse::daemon::parse_config;

namespace {

// The message of the ConfigError raised by `text`, or "" if it parsed.
std::string error_of(const std::string& text) {
  try {
    (void)parse_config(text, "test.toml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return {};
}

}  // namespace

TEST_CASE("config: an empty file gives the documented defaults") {
  const Config c = parse_config("", "empty.toml");
  CHECK(c.audio.device == "default");
  CHECK(c.audio.rate == 48000);
  CHECK(c.audio.channel == -1);
  CHECK(c.gps.host == "127.0.0.1");
  CHECK(c.gps.port == 2947);
  CHECK(c.gps.timeout == Approx(1.5));
  CHECK(c.output.kind == OutputKind::kPty);
  CHECK(c.output.path == "/run/gearpulse/pulse");
  CHECK(c.output.pulses_per_km == Approx(2485.0));
  CHECK(c.model.state_dir == "/var/lib/gearpulse");
  CHECK(c.model.store_hours == Approx(50.0));
  CHECK(c.control.socket == "/run/gearpulse/control.sock");
  CHECK(c.log.level == "info");
}

TEST_CASE("config: the interface keys are read") {
  const Config c = parse_config(R"(
[audio]
device = "hw:1,0"
rate = 8000
[gps]
host = "gps.local"
port = 3000
[output]
kind = "gpio"
path = "/tmp/p"
chip = "gpiochip2"
line = 5
pulses_per_km = 4000.5
[model]
state_dir = "/tmp/state"
[control]
socket = "/tmp/ctl.sock"
)",
                                "ok.toml");
  CHECK(c.audio.device == "hw:1,0");
  CHECK(c.audio.rate == 8000);
  CHECK(c.gps.host == "gps.local");
  CHECK(c.gps.port == 3000);
  CHECK(c.output.kind == OutputKind::kGpio);
  CHECK(c.output.chip == "gpiochip2");
  CHECK(c.output.line == 5);
  CHECK(c.output.pulses_per_km == Approx(4000.5));
  CHECK(c.model.state_dir == "/tmp/state");
  CHECK(c.control.socket == "/tmp/ctl.sock");
}

TEST_CASE("config: an unknown key names file line and key") {
  CHECK(error_of("[audio]\ndevice = \"x\"\n\nrte = 48000\n") == "test.toml:4: audio.rte: unknown key");
  CHECK(error_of("[gps]\nlatency = 0.1\ntimout = 2\n") == "test.toml:3: gps.timout: unknown key");
}

TEST_CASE("config: an unknown section names file line and section") {
  CHECK(
      error_of("[audio]\nrate = 48000\n[outptu]\nkind = \"pty\"\n") ==
      "test.toml:3: outptu: unknown section (the sections are [audio], [tracker], [gps], [output], [model], "
      "[control], [log])");
  CHECK(error_of("verbose = true\n") ==
        "test.toml:1: verbose: a key outside any section (each key belongs under one of [audio], [tracker], "
        "[gps], [output], [model], [control], [log])");
  CHECK(error_of("audio = 5\n") == "test.toml:1: audio: expected a [section]");
}

TEST_CASE("config: a decision lag of more hops than the queue holds names the lag's line") {
  const std::string e = error_of("[tracker]\nhop = 0.005\ndecision_lag = 2\n");
  INFO(e);
  CHECK(e.starts_with("test.toml:3: tracker.decision_lag: tracker: decision lag 2 s is more than"));
  CHECK(e.ends_with("hops of 0.005 s"));
}

TEST_CASE("config: an out of range value names file line and key") {
  const std::string e = error_of("[audio]\nrate = 1000\n");
  CHECK(e.starts_with("test.toml:2: audio.rate: value 1000 out of range"));
  CHECK(error_of("[gps]\nport = 70000\n").starts_with("test.toml:2: gps.port: value 70000 out of range"));
  CHECK(error_of("\n[output]\npulses_per_km = -3\n")
            .starts_with("test.toml:3: output.pulses_per_km: value -3"));
  CHECK(error_of("[model]\nstore_hours = 0\n").starts_with("test.toml:2: model.store_hours: value 0"));
  CHECK(error_of("[output]\nkind = \"usb\"\n") ==
        "test.toml:2: output.kind: 'usb' is not one of pty, gpio, none");
  CHECK(
      error_of("[audio]\nchannels = 2\nchannel = 2\n").starts_with("test.toml:3: audio.channel: channel 2"));
}

TEST_CASE("config: a number above its range or not a number names file line and key") {
  // A timeout of 11 days would keep a lost GPS counted as present; a ring of NaN seconds passes every
  // comparison after it, so both are refused where they are read.
  CHECK(error_of("[gps]\ntimeout = 1e6\n").starts_with("test.toml:2: gps.timeout: value 1e+06 out of range"));
  CHECK(error_of("[audio]\nring_seconds = nan\n").starts_with("test.toml:2: audio.ring_seconds: value "));
  CHECK(error_of("[audio]\nring_seconds = inf\n").starts_with("test.toml:2: audio.ring_seconds: value "));
  CHECK(error_of("[gps]\ntimeout = 60\n").empty());
}

TEST_CASE("config: an empty string is refused") {
  // An empty device name is a value left out, not a device: it is refused at its line instead of reaching
  // ALSA when the daemon starts.
  CHECK(error_of("[audio]\ndevice = \"\"\n") == "test.toml:2: audio.device: must not be empty");
}

TEST_CASE("config: a wrong type names file line and key") {
  CHECK(error_of("[audio]\nrate = \"fast\"\n") == "test.toml:2: audio.rate: expected an integer");
  CHECK(error_of("[gps]\nhost = 12\n") == "test.toml:2: gps.host: expected a string");
  CHECK(error_of("[audio]\nrealtime = 1\n") == "test.toml:2: audio.realtime: expected true or false");
  CHECK(error_of("[output]\npulses_per_km = \"2485\"\n") ==
        "test.toml:2: output.pulses_per_km: expected a number");
  CHECK(error_of("[audio]\nrate = 48000.5\n") == "test.toml:2: audio.rate: expected an integer");
}

TEST_CASE("config: malformed TOML names file, line and column") {
  // FILE:LINE:COLUMN: reason, the column a number from 1.
  const auto at = [](const std::string& e, const std::string& file_line) {
    INFO(e);
    REQUIRE(e.starts_with(file_line + ":"));
    const std::size_t digits = e.find_first_not_of("0123456789", file_line.size() + 1);
    CHECK(digits > file_line.size() + 1);
    CHECK(e.compare(digits, 2, ": ") == 0);
  };
  at(error_of("[audio]\nrate = 48000\n[gps\nport = 1\n"), "test.toml:3");
  at(error_of("[audio]\ndevice = \"unterminated\n"), "test.toml:2");
  at(error_of("[audio]\nrate = 1\nrate = 2\n"), "test.toml:3");
}

TEST_CASE("config: relations between keys are checked") {
  CHECK(error_of("[tracker]\nband_low = 300\nband_high = 200\n") ==
        "test.toml:3: tracker.band_high: tracker.band_high (200 Hz) must be above tracker.band_low (300 Hz)");
  CHECK(error_of("[audio]\nrate = 8000\n[tracker]\nband_high = 4500\n")
            .starts_with("test.toml:4: tracker.band_high: tracker.band_high (4500 Hz) must be at most"));
  // Below Nyquist but beyond the tracker's rate / 2.5.
  CHECK(error_of("[audio]\nrate = 8000\n[tracker]\nband_high = 3500\n") ==
        "test.toml:4: tracker.band_high: tracker.band_high (3500 Hz) must be at most audio.rate / 2.5 (3200 "
        "Hz)");
  CHECK(error_of("[audio]\nrate = 8000\n[tracker]\nband_high = 3200\nwindow = 0.16\n").empty());
  CHECK(error_of("[output]\npulse_width = 0.01\nmax_frequency = 500\n")
            .starts_with("test.toml:2: output.pulse_width:"));
  CHECK(error_of("[output]\nmin_frequency = 5\nmax_frequency = 2\n")
            .starts_with("test.toml:3: output.max_frequency:"));
  // A train that never stops at standstill is one the pulse scheduler refuses at start: refused here, so
  // --check-config and the daemon's start catch it (exit 2, which the unit does not restart on).
  CHECK(error_of("[output]\nmin_frequency = 0\n").starts_with("test.toml:2: output.min_frequency:"));
  // A relation broken by the one key the file sets is reported at that key, by its line and name, not
  // against the other key of the pair, which the file does not set.
  CHECK(error_of("[tracker]\nband_low = 300\n") ==
        "test.toml:2: tracker.band_low: tracker.band_high (200 Hz) must be above tracker.band_low (300 Hz)");
  CHECK(error_of("[tracker]\nhop = 0.7\n") ==
        "test.toml:2: tracker.hop: tracker: hop 0.7 s is more than 4 windows (0.64 s): the audio between "
        "windows would be ignored");
  CHECK(error_of("[output]\nmin_frequency = 1000\n").starts_with("test.toml:2: output.min_frequency:"));
  // A ring that cannot hold two capture periods dropped about half the audio, with nothing said.
  CHECK(error_of("[audio]\nrate = 16000\nperiod_frames = 4096\nring_seconds = 0.1\n") ==
        "test.toml:4: audio.ring_seconds: audio.ring_seconds (0.1 s) must hold two periods of 4096 frames at "
        "16000 Hz (0.512 s)");
  CHECK(error_of("[audio]\nrate = 16000\nperiod_frames = 4096\nring_seconds = 0.6\n").empty());
  CHECK(error_of("[output]\nmax_frequency = 100000\n").starts_with("test.toml:2: output.max_frequency:"));
  // A store that cannot hold the new pairs a retrain waits for never retrained after the young schedule.
  CHECK(error_of("[model]\nmax_samples = 500\n") ==
        "test.toml:2: model.max_samples: model.min_new_samples (600 pairs) must be at most what the store "
        "holds: model.max_samples (500) and model.store_hours (50 h, 180000 pairs at one a second)");
  CHECK(error_of("[model]\nstore_hours = 0.1\n").starts_with("test.toml:2: model.store_hours:"));
  CHECK(error_of("[model]\nmin_new_samples = 2000000\n").starts_with("test.toml:2: model.min_new_samples:"));
  CHECK(error_of("[model]\nmax_samples = 600\nstore_hours = 0.17\n").empty());
}

TEST_CASE("config: every accepted output section is one the pulse scheduler takes") {
  for (const char* text :
       {"", "[output]\nduty = 0.5\n", "[output]\nmin_frequency = 0.001\nmax_frequency = 1.5\n",
        "[output]\npulse_width = 0.0009\nmax_frequency = 1000\n"}) {
    INFO(text);
    const Config c = parse_config(text, "a");
    CHECK_NOTHROW(gearpulse::validate(gearpulse::daemon::pulse_config_of(c.output)));
  }
}

TEST_CASE("config: every accepted tracker section is one the tracker takes at the configured rate") {
  // What the tracker would refuse when the daemon opens the audio is refused by the config (so by
  // --check-config), with the line of the key to change.
  CHECK(error_of("[tracker]\nband_low = 20.0\n")
            .starts_with("test.toml:2: tracker.band_low: tracker: window 0.16 s is too short"));
  CHECK(error_of("[tracker]\nband_low = 30.0\nwindow = 0.1\n")
            .starts_with("test.toml:3: tracker.window: tracker: window"));
  CHECK(error_of("[tracker]\nwindow = 0.05\n")
            .starts_with("test.toml:2: tracker.window: tracker: window 0.05 s"));
  CHECK(error_of("[tracker]\nband_low = 30.0\nwindow = 0.14\n").empty());
  int accepted = 0;
  for (const char* rate : {"8000", "48000"})
    for (const char* low : {"10", "30", "50", "120"})
      for (const char* high : {"200", "1000", "3500"})
        for (const char* window : {"0.01", "0.05", "0.1", "0.5", "2.0"})
          for (const char* hop : {"0.001", "0.1", "1.0"}) {
            const std::string text = std::string("[audio]\nrate = ") + rate +
                                     "\n[tracker]\nband_low = " + low + "\nband_high = " + high +
                                     "\nwindow = " + window + "\nhop = " + hop + "\n";
            INFO(text);
            try {
              const Config c = parse_config(text, "a");
              ++accepted;
              CHECK(gearpulse::SlidingDftTracker::validate(
                        gearpulse::daemon::tracker_config_of(c.tracker, c.audio.rate))
                        .empty());
            } catch (const ConfigError&) {
            }
          }
  CHECK(accepted > 20);
}

TEST_CASE("config: channel takes an index or mix") {
  CHECK(parse_config("[audio]\nchannels = 2\nchannel = 1\n", "a").audio.channel == 1);
  CHECK(parse_config("[audio]\nchannels = 2\nchannel = \"mix\"\n", "a").audio.channel == -1);
  CHECK(error_of("[audio]\nchannel = \"left\"\n").starts_with("test.toml:2: audio.channel:"));
}

TEST_CASE("config: the shipped default config is valid") {
  const Config c = gearpulse::daemon::load_config(GEARPULSE_SOURCE_DIR "/config/gearpulse.toml");
  const Config d = parse_config("", "empty");
  // The file documents the defaults: loading it changes nothing.
  CHECK(gearpulse::daemon::restart_required_changes(c, d).empty());
  CHECK(c.model.retrain_interval == d.model.retrain_interval);
  CHECK(c.log.level == d.log.level);
}

TEST_CASE("config: a missing file is an error naming it") {
  try {
    (void)gearpulse::daemon::load_config("/nonexistent/gearpulse.toml");
    FAIL("no error");
  } catch (const ConfigError& e) {
    CHECK(std::string(e.what()).starts_with("/nonexistent/gearpulse.toml: "));
  }
}

TEST_CASE("config: a directory given as the file is an error naming it") {
  // An ifstream opens a directory, and reading it gave an empty text: every default, "configuration OK".
  const std::string dir = std::filesystem::temp_directory_path().string();
  try {
    (void)gearpulse::daemon::load_config(dir);
    FAIL("no error");
  } catch (const ConfigError& e) {
    CHECK(std::string(e.what()) == dir + ": cannot read config file: is a directory");
  }
}

TEST_CASE("config: a device, a FIFO or an overlong file is refused unread, naming it") {
  // /dev/zero never ends (it was read until bad_alloc); a FIFO blocked the reader until a writer came.
  const gearpulse::test::TempDir dir;
  const std::string fifo = (dir / "fifo.toml").string();
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  const std::string big = (dir / "big.toml").string();
  // Valid TOML (one comment) of exactly the bound is read; one byte more is refused for its length.
  const std::string text = "#" + std::string(gearpulse::daemon::kMaxConfigBytes - 2, 'x') + "\n";
  gearpulse::test::write_text(big, text);
  CHECK_NOTHROW(gearpulse::daemon::load_config(big));
  gearpulse::test::write_text(big, text + "\n");
  const std::pair<std::string, std::string> cases[] = {
      {"/dev/zero", "not a regular file"},
      {fifo, "not a regular file"},
      {big, "longer than 1048576 bytes"},
  };
  for (const auto& [path, reason] : cases) {
    CAPTURE(path);
    CHECK_THROWS_WITH(gearpulse::daemon::load_config(path),
                      Catch::Matchers::StartsWith(path + ": cannot read config file: " + reason));
  }
}

TEST_CASE("config: relative paths are taken from the config file's directory") {
  // Under systemd the daemon's working directory is /: "state" must not become /state.
  const gearpulse::test::TempDir dir;
  std::filesystem::create_directories(dir / "etc");
  const auto file = dir / "etc/gearpulse.toml";
  std::ofstream(file) << "[output]\npath = \"pulse\"\n[model]\nstate_dir = \"../state\"\n"
                         "[control]\nsocket = \"/run/x/ctl.sock\"\n";
  const Config c = gearpulse::daemon::load_config(file.string());
  CHECK(c.output.path == (dir / "etc/pulse").string());
  CHECK(c.model.state_dir == (dir / "state").string());
  CHECK(c.control.socket == "/run/x/ctl.sock");  // absolute: as written
  // From text with no file, as written.
  CHECK(parse_config("[model]\nstate_dir = \"s\"\n", "a").model.state_dir == "s");
  // The socket's length limit applies to the path the daemon will bind.
  std::ofstream(file) << "[control]\nsocket = \"" << std::string(100, 'x') << "\"\n";
  CHECK_THROWS_WITH(gearpulse::daemon::load_config(file.string()),
                    Catch::Matchers::Contains("control.socket: path longer than 107 bytes"));
}

TEST_CASE("config: changes that need a restart are named") {
  const Config a = parse_config("", "a");
  const Config b = parse_config(
      "[audio]\ndevice = \"hw:2\"\n[log]\nlevel = \"debug\"\n[model]\nmin_new_samples = 5\n", "b");
  const auto changed = gearpulse::daemon::restart_required_changes(a, b);
  REQUIRE(changed.size() == 1);
  CHECK(changed[0] == "audio.device");
  // Each key by its dotted name, as the configuration's documentation lists them.
  const auto several = gearpulse::daemon::restart_required_changes(
      a, parse_config("[audio]\nrate = 8000\n[tracker]\nband_high = 3000\nhop = 0.05\n[output]\nduty = 0.4\n"
                      "[control]\nmax_clients = 2\n",
                      "b"));
  CHECK(several == std::vector<std::string>{"audio.rate", "tracker.band_high", "tracker.hop", "output.duty",
                                            "control.max_clients"});
}

TEST_CASE("config: a reload changing the GPS timeout or the state directory needs a restart") {
  // The GPS client is made with its timeout, and the state directory is locked and holds the model and the
  // training store from start on: a reload moves neither, so both must be named to the user.
  const Config a = parse_config("", "a");
  const auto gps = gearpulse::daemon::restart_required_changes(a, parse_config("[gps]\ntimeout = 3\n", "b"));
  REQUIRE(gps.size() == 1);
  CHECK(gps[0] == "gps.timeout");
  const auto state =
      gearpulse::daemon::restart_required_changes(a, parse_config("[model]\nstate_dir = \"/tmp/s\"\n", "b"));
  REQUIRE(state.size() == 1);
  CHECK(state[0] == "model.state_dir");
}
