#include "daemon/config.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <set>
#include <sstream>
#include <string_view>
#include <system_error>

#include <toml++/toml.h>

#include "common/atomic_file.hpp"
#include "daemon/training_store.hpp"

namespace gearpulse::daemon {
namespace {

// A number as a user would write it: 300, 0.05, 1e+06.
std::string format_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

std::string where(const std::string& file, const toml::source_region& region) {
  std::string out = file;
  if (region.begin.line > 0) out += ":" + std::to_string(region.begin.line);
  return out;
}

// Reads one [section]: every key read is remembered so that the rest can be reported as unknown.
class Section {
 public:
  Section(const toml::table* table, std::string name, const std::string& file)
      : table_(table), name_(std::move(name)), file_(file) {}

  void string(std::string_view key, std::string& out) {
    const toml::node* node = find(key);
    if (!node) return;
    const auto* value = node->as_string();
    if (!value) fail(*node, key, "expected a string");
    if (value->get().empty()) fail(*node, key, "must not be empty");
    out = value->get();
  }

  void boolean(std::string_view key, bool& out) {
    const toml::node* node = find(key);
    if (!node) return;
    const auto* value = node->as_boolean();
    if (!value) fail(*node, key, "expected true or false");
    out = value->get();
  }

  // Accepts integers and floats.
  void number(std::string_view key, double& out, double lo, double hi) {
    const toml::node* node = find(key);
    if (!node) return;
    double v = 0.0;
    if (const auto* f = node->as_floating_point())
      v = f->get();
    else if (const auto* i = node->as_integer())
      v = static_cast<double>(i->get());
    else
      fail(*node, key, "expected a number");
    if (!std::isfinite(v) || v < lo || v > hi) fail(*node, key, range_text(v, lo, hi));
    out = v;
  }

  template <typename Int>
  void integer(std::string_view key, Int& out, std::int64_t lo, std::int64_t hi) {
    const toml::node* node = find(key);
    if (!node) return;
    const auto* i = node->as_integer();
    if (!i) fail(*node, key, "expected an integer");
    const std::int64_t v = i->get();
    if (v < lo || v > hi)
      fail(*node, key,
           "value " + std::to_string(v) + " out of range [" + std::to_string(lo) + ", " + std::to_string(hi) +
               "]");
    out = static_cast<Int>(v);
  }

  // A string that must be one of `choices`.
  std::string choice(std::string_view key, const std::string& current,
                     std::initializer_list<std::string_view> choices) {
    const toml::node* node = find(key);
    if (!node) return current;
    const auto* value = node->as_string();
    std::string allowed;
    for (auto c : choices)
      allowed += (allowed.empty() ? "" : ", ") + std::string(c);
    if (!value) fail(*node, key, "expected one of " + allowed);
    for (auto c : choices)
      if (value->get() == c) return value->get();
    fail(*node, key, "'" + value->get() + "' is not one of " + allowed);
  }

  // Raw access for keys with mixed types (e.g. audio.channel = 0 or "mix").
  const toml::node* raw(std::string_view key) { return find(key); }

  [[noreturn]] void fail(const toml::node& node, std::string_view key, const std::string& reason) const {
    throw ConfigError(where(file_, node.source()) + ": " + name_ + "." + std::string(key) + ": " + reason);
  }

  // Every key that nobody asked for is a typo or a key of another version: refuse it.
  void reject_unknown() const {
    if (!table_) return;
    for (auto&& [key, node] : *table_) {
      if (known_.count(std::string(key.str()))) continue;
      const auto& region = key.source().begin.line > 0 ? key.source() : node.source();
      throw ConfigError(where(file_, region) + ": " + name_ + "." + std::string(key.str()) + ": unknown key");
    }
  }

 private:
  const toml::node* find(std::string_view key) {
    known_.insert(std::string(key));
    return table_ ? table_->get(key) : nullptr;
  }
  static std::string range_text(double v, double lo, double hi) {
    std::ostringstream s;
    s << "value " << v << " out of range [" << lo << ", " << hi << "]";
    return s.str();
  }

  const toml::table* table_;
  std::string name_;
  const std::string& file_;
  std::set<std::string> known_;
};

void read_audio(Section& s, AudioConfig& a) {
  s.string("device", a.device);
  s.integer("rate", a.rate, 5100, 384000);
  s.integer("channels", a.channels, 1, 32);
  if (const toml::node* node = s.raw("channel")) {
    if (const auto* text = node->as_string()) {
      if (text->get() != "mix") s.fail(*node, "channel", "expected a channel index or \"mix\"");
      a.channel = -1;
    } else if (const auto* i = node->as_integer()) {
      if (i->get() < 0 || i->get() >= static_cast<std::int64_t>(a.channels))
        s.fail(*node, "channel",
               "channel " + std::to_string(i->get()) + " out of range [0, " + std::to_string(a.channels - 1) +
                   "]");
      a.channel = static_cast<int>(i->get());
    } else {
      s.fail(*node, "channel", "expected a channel index or \"mix\"");
    }
  }
  a.format = s.choice("format", a.format, {"auto", "S16_LE", "S32_LE", "FLOAT_LE"});
  s.integer("period_frames", a.period_frames, 16, 65536);
  s.boolean("realtime", a.realtime);
  s.integer("rt_priority", a.rt_priority, 1, 99);
  s.number("ring_seconds", a.ring_seconds, 0.1, 60.0);
}

void read_tracker(Section& s, TrackerSection& t) {
  s.number("band_low", t.band_low, 1.0, 20000.0);
  s.number("band_high", t.band_high, 1.0, 20000.0);
  s.number("window", t.window, 0.01, 2.0);
  s.number("hop", t.hop, 0.005, 2.0);
  s.number("decision_lag", t.decision_lag, 0.0, 2.0);
  s.number("min_snr_db", t.min_snr_db, -30.0, 60.0);
}

void read_gps(Section& s, GpsConfig& g) {
  s.string("host", g.host);
  s.integer("port", g.port, 1, 65535);
  s.number("latency", g.latency, 0.0, kMaxGpsLatency);
  s.number("timeout", g.timeout, 0.1, 60.0);
}

void read_output(Section& s, OutputConfig& o) {
  const std::string kind = s.choice("kind", to_string(o.kind), {"pty", "gpio", "none"});
  o.kind = kind == "pty" ? OutputKind::kPty : kind == "gpio" ? OutputKind::kGpio : OutputKind::kNone;
  s.string("path", o.path);
  s.string("chip", o.chip);
  s.integer("line", o.line, 0, 4095);
  s.number("pulses_per_km", o.pulses_per_km, 1.0, 1.0e6);
  s.number("pulse_width", o.pulse_width, 1.0e-6, 1.0);
  s.number("duty", o.duty, 0.0, 0.9);
  s.number("min_frequency", o.min_frequency, 0.001, 1000.0);
  s.number("max_frequency", o.max_frequency, 1.0, 100000.0);
}

void read_model(Section& s, ModelConfig& m) {
  s.string("state_dir", m.state_dir);
  s.number("retrain_interval", m.retrain_interval, 1.0, 7.0 * 86400.0);
  s.integer("min_new_samples", m.min_new_samples, 1, 100'000'000);
  s.integer("replace_min_samples", m.replace_min_samples, 0, 100'000'000);
  s.integer("learn_cluster_pairs", m.learn_cluster_pairs, 10, 100'000);
  s.number("learn_first_refit", m.learn_first_refit, 10.0, 86400.0);
  s.number("learn_young_time", m.learn_young_time, 0.0, 7.0 * 86400.0);
  s.number("store_hours", m.store_hours, 0.01, 24.0 * 365.0);
  s.integer("max_samples", m.max_samples, 100, static_cast<std::int64_t>(kMaxStoreSamples));
  s.number("save_interval", m.save_interval, 1.0, 86400.0);
}

void read_control(Section& s, ControlConfig& c) {
  s.string("socket", c.socket);
  s.integer("max_clients", c.max_clients, 1, 1024);
}

void read_log(Section& s, LogConfig& l) {
  l.level = s.choice("level", l.level, {"trace", "debug", "info", "warn", "error", "critical", "off"});
}

// Checks between keys, after every key on its own is known to be valid. Each error points at the first of
// the keys involved that the file sets, by its line, and names it (a relation broken by one key the user
// wrote is not reported against another he did not), else at the file.
void check_relations(const Config& c, const toml::table& root, const std::string& file) {
  const auto fail = [&](std::initializer_list<std::string_view> keys, const std::string& what) {
    for (std::string_view key : keys)
      if (const toml::node* n = root.at_path(key).node())
        throw ConfigError(where(file, n->source()) + ": " + std::string(key) + ": " + what);
    throw ConfigError(file + ": " + std::string(*keys.begin()) + ": " + what);
  };
  const auto hz = [](double v) { return format_number(v) + " Hz"; };
  if (c.tracker.band_high <= c.tracker.band_low)
    fail({"tracker.band_high", "tracker.band_low"}, "tracker.band_high (" + hz(c.tracker.band_high) +
                                                        ") must be above tracker.band_low (" +
                                                        hz(c.tracker.band_low) + ")");
  // The tracker's own bound (SlidingDftTracker::validate): the band's top at most rate / 2.5, short of
  // Nyquist by the decimating filter's transition band.
  if (c.tracker.band_high > c.audio.rate / 2.5)
    fail({"tracker.band_high", "audio.rate"}, "tracker.band_high (" + hz(c.tracker.band_high) +
                                                  ") must be at most audio.rate / 2.5 (" +
                                                  hz(c.audio.rate / 2.5) + ")");
  // Whatever else the tracker would refuse at the configured rate (the window must hold 4 periods of
  // band_low, ...), refused here, before any device is opened.
  if (const std::string problem = SlidingDftTracker::validate(tracker_config_of(c.tracker, c.audio.rate));
      !problem.empty()) {
    // Point at the keys the problem is about: the window (or the band edge it must hold), the hop, the
    // decision lag (in hops), else the band's upper edge against the rate.
    if (problem.starts_with("window"))
      fail({"tracker.window", "tracker.band_low"}, "tracker: " + problem);
    else if (problem.starts_with("hop"))
      fail({"tracker.hop", "tracker.window"}, "tracker: " + problem);
    else if (problem.starts_with("decision lag"))
      fail({"tracker.decision_lag", "tracker.hop"}, "tracker: " + problem);
    else
      fail({"tracker.band_high", "tracker.band_low", "audio.rate"}, "tracker: " + problem);
  }
  // The capture pushes a period at a time into the ring: one that cannot hold two drops audio at every
  // period the tracker has not yet taken.
  if (c.audio.ring_seconds * c.audio.rate < 2.0 * c.audio.period_frames)
    fail({"audio.ring_seconds", "audio.period_frames", "audio.rate"},
         "audio.ring_seconds (" + format_number(c.audio.ring_seconds) + " s) must hold two periods of " +
             std::to_string(c.audio.period_frames) + " frames at " + hz(c.audio.rate) + " (" +
             format_number(2.0 * c.audio.period_frames / c.audio.rate) + " s)");
  // sun_path holds 108 bytes including the terminator.
  if (c.control.socket.size() > 107)
    fail({"control.socket"}, "path longer than 107 bytes: " + c.control.socket);
  if (c.output.max_frequency <= c.output.min_frequency)
    fail({"output.max_frequency", "output.min_frequency"},
         "output.max_frequency (" + hz(c.output.max_frequency) + ") must be above output.min_frequency (" +
             hz(c.output.min_frequency) + ")");
  // A fixed-width pulse must fit in the shortest period, or pulses would merge.
  if (c.output.duty == 0.0 && c.output.pulse_width * c.output.max_frequency >= 1.0)
    fail({"output.pulse_width", "output.max_frequency"},
         "output.pulse_width (" + format_number(c.output.pulse_width) +
             " s) is not shorter than the period at output.max_frequency (" + hz(c.output.max_frequency) +
             ")");
  // Whatever the pulse scheduler would refuse at start is refused here, where --check-config sees it.
  try {
    validate(pulse_config_of(c.output));
  } catch (const std::invalid_argument& e) {
    fail({"output.min_frequency", "output.max_frequency", "output.pulse_width", "output.duty"},
         std::string("[output]: ") + e.what());
  }
  // A retrain waits for model.min_new_samples new pairs, and the store counts no more new pairs than it
  // holds: a store smaller than that (by its cap, or by the hours it keeps at one pair a second) would
  // never retrain again once the young model's schedule ended, with nothing said.
  const double held =
      std::min(static_cast<double>(c.model.max_samples), std::floor(c.model.store_hours * 3600.0));
  if (static_cast<double>(c.model.min_new_samples) > held)
    fail({"model.min_new_samples", "model.max_samples", "model.store_hours"},
         "model.min_new_samples (" + std::to_string(c.model.min_new_samples) +
             " pairs) must be at most what the store holds: model.max_samples (" +
             std::to_string(c.model.max_samples) + ") and model.store_hours (" +
             format_number(c.model.store_hours) + " h, " +
             format_number(std::floor(c.model.store_hours * 3600.0)) + " pairs at one a second)");
}

// A relative path in the file is taken from the file's own directory, as the file's author sees it: under
// systemd the daemon runs from /, not from where the file lives.
void resolve_paths(Config& c, const std::filesystem::path& base) {
  if (base.empty()) return;
  for (std::string* p : {&c.output.path, &c.model.state_dir, &c.control.socket})
    if (!p->empty() && std::filesystem::path(*p).is_relative()) *p = (base / *p).lexically_normal().string();
}

Config from_table(const toml::table& root, const std::string& file, const std::filesystem::path& base) {
  Config config;
  config.source = file;
  static constexpr std::string_view kSections[] = {"audio", "tracker", "gps", "output",
                                                   "model", "control", "log"};
  for (auto&& [key, node] : root) {
    bool known = false;
    for (auto s : kSections)
      known = known || key.str() == s;
    const auto& region = key.source().begin.line > 0 ? key.source() : node.source();
    if (!known) {
      std::string list;
      for (auto s : kSections)
        list += (list.empty() ? "[" : ", [") + std::string(s) + "]";
      throw ConfigError(where(file, region) + ": " + std::string(key.str()) +
                        (node.is_table()
                             ? ": unknown section (the sections are " + list + ")"
                             : ": a key outside any section (each key belongs under one of " + list + ")"));
    }
    if (!node.is_table())
      throw ConfigError(where(file, region) + ": " + std::string(key.str()) + ": expected a [section]");
  }
  // Every section is read the same way: its keys, then a refusal of any key it does not know.
  const auto section = [&](const char* name, auto read, auto& into) {
    Section s(root.get_as<toml::table>(name), name, file);
    read(s, into);
    s.reject_unknown();
  };
  section("audio", read_audio, config.audio);
  section("tracker", read_tracker, config.tracker);
  section("gps", read_gps, config.gps);
  section("output", read_output, config.output);
  section("model", read_model, config.model);
  section("control", read_control, config.control);
  section("log", read_log, config.log);
  resolve_paths(config, base);
  check_relations(config, root, file);
  return config;
}

}  // namespace

std::string output_target(const OutputConfig& o) {
  switch (o.kind) {
    case OutputKind::kPty:
      return o.path;
    case OutputKind::kGpio:
      return o.chip + ":" + std::to_string(o.line);
    case OutputKind::kNone:
      break;
  }
  return "";
}

PulseConfig pulse_config_of(const OutputConfig& o) noexcept {
  PulseConfig p;
  p.pulses_per_km = o.pulses_per_km;
  p.pulse_width_s = o.duty > 0.0 ? 0.0 : o.pulse_width;
  p.duty = o.duty > 0.0 ? o.duty : 0.5;
  p.min_freq_hz = o.min_frequency;
  p.max_freq_hz = o.max_frequency;
  return p;
}

gearpulse::TrackerConfig tracker_config_of(const TrackerSection& t, double sample_rate_hz) noexcept {
  gearpulse::TrackerConfig tc;
  tc.sample_rate_hz = sample_rate_hz;
  tc.window_s = t.window;
  tc.hop_s = t.hop;
  tc.decision_lag_s = t.decision_lag;
  tc.band_lo_hz = t.band_low;
  tc.band_hi_hz = t.band_high;
  // at() serves GPS fixes up to a few seconds old, with the latency on top: the largest the config
  // accepts, since a reload may raise it while this tracker runs (a few dozen points more); and with a
  // decision lag the fixes wait that much longer, for their hops' decided confidence.
  tc.history_s = kMaxGpsLatency + 2.0 + t.decision_lag;
  return tc;
}

const char* to_string(OutputKind kind) noexcept {
  switch (kind) {
    case OutputKind::kPty:
      return "pty";
    case OutputKind::kGpio:
      return "gpio";
    case OutputKind::kNone:
      return "none";
  }
  return "none";
}

Config parse_config(std::string_view text, const std::string& source_name,
                    const std::filesystem::path& base_dir) {
  toml::table root;
  try {
    root = toml::parse(text, std::string_view(source_name));
  } catch (const toml::parse_error& e) {
    // No key to name: the column says where on the line the syntax broke.
    std::string at = where(source_name, e.source());
    if (e.source().begin.line > 0 && e.source().begin.column > 0)
      at += ":" + std::to_string(e.source().begin.column);
    throw ConfigError(at + ": " + std::string(e.description()));
  }
  return from_table(root, source_name, base_dir);
}

Config load_config(const std::string& path) {
  std::optional<std::string> text;
  try {
    text = read_file(path, kMaxConfigBytes);
  } catch (const FileRefused& e) {
    throw ConfigError(path + ": cannot read config file: " + e.reason());
  } catch (const std::system_error& e) {
    throw ConfigError(path + ": cannot read config file: " + e.code().message());
  }
  if (!text) throw ConfigError(path + ": cannot open config file: " + std::strerror(ENOENT));
  std::error_code ec;
  return parse_config(*text, path, std::filesystem::absolute(path, ec).parent_path());
}

std::vector<std::string> restart_required_changes(const Config& a, const Config& b) {
  std::vector<std::string> changed;
  const auto check = [&](bool differs, const char* key) {
    if (differs) changed.emplace_back(key);
  };
  check(a.audio.device != b.audio.device, "audio.device");
  check(a.audio.rate != b.audio.rate, "audio.rate");
  check(a.audio.channels != b.audio.channels, "audio.channels");
  check(a.audio.channel != b.audio.channel, "audio.channel");
  check(a.audio.format != b.audio.format, "audio.format");
  check(a.audio.period_frames != b.audio.period_frames, "audio.period_frames");
  check(a.audio.realtime != b.audio.realtime, "audio.realtime");
  check(a.audio.rt_priority != b.audio.rt_priority, "audio.rt_priority");
  check(a.audio.ring_seconds != b.audio.ring_seconds, "audio.ring_seconds");
  check(a.tracker.band_low != b.tracker.band_low, "tracker.band_low");
  check(a.tracker.band_high != b.tracker.band_high, "tracker.band_high");
  check(a.tracker.window != b.tracker.window, "tracker.window");
  check(a.tracker.hop != b.tracker.hop, "tracker.hop");
  check(a.tracker.decision_lag != b.tracker.decision_lag, "tracker.decision_lag");
  check(a.gps.host != b.gps.host, "gps.host");
  check(a.gps.port != b.gps.port, "gps.port");
  check(a.gps.timeout != b.gps.timeout, "gps.timeout");
  check(a.output.kind != b.output.kind, "output.kind");
  check(a.output.path != b.output.path, "output.path");
  check(a.output.chip != b.output.chip, "output.chip");
  check(a.output.line != b.output.line, "output.line");
  check(a.output.pulses_per_km != b.output.pulses_per_km, "output.pulses_per_km");
  check(a.output.pulse_width != b.output.pulse_width, "output.pulse_width");
  check(a.output.duty != b.output.duty, "output.duty");
  check(a.output.min_frequency != b.output.min_frequency, "output.min_frequency");
  check(a.output.max_frequency != b.output.max_frequency, "output.max_frequency");
  check(a.model.state_dir != b.model.state_dir, "model.state_dir");
  check(a.control.socket != b.control.socket, "control.socket");
  check(a.control.max_clients != b.control.max_clients, "control.max_clients");
  return changed;
}

}  // namespace gearpulse::daemon
