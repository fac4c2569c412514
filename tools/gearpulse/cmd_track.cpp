// gearpulse track: engine-frequency track of a lighter-voltage recording, as CSV t,freq,snr_db (with
// --confidence, a fourth column and the estimate of every hop, trusted or not).
#include <sndfile.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/sliding_dft_tracker.hpp"
#include "tools/gearpulse/commands.hpp"
#include "tools/gearpulse/number_option.hpp"

namespace gearpulse::cli {
namespace {

// The tracker's own defaults (TrackerConfig), as the daemon's [tracker] section has them.
std::string default_band() {
  const TrackerConfig defaults;
  char text[64];
  std::snprintf(text, sizeof text, "%g:%g", defaults.band_lo_hz, defaults.band_hi_hz);
  return text;
}

struct TrackOptions {
  std::string band = default_band();
  double hop_s = TrackerConfig{}.hop_s;
  double window_s = TrackerConfig{}.window_s;
  int channel = -1;  // -1: mix all channels
  double max_slew = TrackerConfig{}.max_slew_hz_per_s;
  double decision_lag_s = TrackerConfig{}.decision_lag_s;
  bool any_line = false;
  bool confidence = false;
  std::string file;
};

struct SndfileCloser {
  void operator()(SNDFILE* f) const noexcept { sf_close(f); }
};

void parse_band(const std::string& text, TrackerConfig& config) {
  const auto colon = text.find(':');
  std::size_t used_lo = 0, used_hi = 0;
  try {
    if (colon == std::string::npos) throw std::invalid_argument("no colon");
    config.band_lo_hz = std::stod(text.substr(0, colon), &used_lo);
    config.band_hi_hz = std::stod(text.substr(colon + 1), &used_hi);
  } catch (const std::exception&) {
    throw UsageError("track: --band '" + text + "' is not LO:HI in Hz");
  }
  if (used_lo != colon || used_hi != text.size() - colon - 1)
    throw UsageError("track: --band '" + text + "' is not LO:HI in Hz");
}

bool readable_encoding(int format) {
  switch (format & SF_FORMAT_SUBMASK) {
    case SF_FORMAT_PCM_S8:
    case SF_FORMAT_PCM_U8:
    case SF_FORMAT_PCM_16:
    case SF_FORMAT_PCM_24:
    case SF_FORMAT_PCM_32:
    case SF_FORMAT_FLOAT:
    case SF_FORMAT_DOUBLE:
    case SF_FORMAT_ULAW:
    case SF_FORMAT_ALAW:
      return true;
    default:
      return false;
  }
}

// A data chunk size that a recorder writing to a pipe, or one cut off before it could finish its header,
// leaves as a placeholder for "unknown length": not a size the recording ever had.
bool placeholder_size(long long declared) {
  return declared == 0xFFFFFFFFLL || declared == 0x7FFFFFFFLL || declared == 0xFFFFFFFFLL - 8 ||
         declared == 0x7FFFFFFFLL - 8;
}

// libsndfile opens a WAV whose data chunk runs past the end of the file and quietly reads what is
// there; its log says "data : <declared> (should be <actual>)". A cut recording is bad input, unless its
// header declares no real length (a streamed or interrupted recording: `streamed` is set, and what is
// there is read).
bool truncated(SNDFILE* file, long long& declared, long long& actual, bool& streamed) {
  std::string log(16384, '\0');
  sf_command(file, SFC_GET_LOG_INFO, log.data(), static_cast<int>(log.size()));
  for (std::size_t at = log.find("data"); at != std::string::npos; at = log.find("data", at + 4)) {
    if (at != 0 && log[at - 1] != '\n') continue;
    const std::size_t eol = log.find('\n', at);
    const std::string line = log.substr(at, eol == std::string::npos ? std::string::npos : eol - at);
    if (std::sscanf(line.c_str(), "data : %lld (should be %lld)", &declared, &actual) == 2 &&
        declared > actual) {
      streamed = placeholder_size(declared);
      return !streamed;
    }
  }
  return false;
}

// A WAV whose data chunk still declares 0 bytes while audio follows it: a recorder stopped before it went
// back to write the length (libsndfile itself writes 0 until it closes a file). libsndfile reads no frames
// from it; it is read through a view of the file in which the chunk declares what the file holds, as a
// header that gives no length is.
class UnfinishedWav {
  struct Key {  // the constructor's passkey: a view is made by open() alone
    explicit Key() = default;
  };

 public:
  // The view of `path` when it is such a WAV, else none. It stays where it was made: libsndfile holds its
  // address.
  static std::unique_ptr<UnfinishedWav> open(const std::string& path) {
    auto wav = std::make_unique<UnfinishedWav>(Key{});
    wav->file_.reset(std::fopen(path.c_str(), "rb"));
    if (!wav->file_ || std::fseek(wav->file_.get(), 0, SEEK_END) != 0) return nullptr;
    wav->length_ = ftello(wav->file_.get());
    unsigned char head[12];
    if (!wav->read_at(0, head, 12) || std::memcmp(head, "RIFF", 4) != 0 ||
        std::memcmp(head + 8, "WAVE", 4) != 0)
      return nullptr;
    for (sf_count_t at = 12; at + 8 <= wav->length_;) {  // the chunks, to the data chunk
      unsigned char chunk[8];
      if (!wav->read_at(at, chunk, 8)) return nullptr;
      const std::uint32_t size =
          chunk[4] | chunk[5] << 8 | chunk[6] << 16 | static_cast<std::uint32_t>(chunk[7]) << 24;
      if (std::memcmp(chunk, "data", 4) == 0) {
        const sf_count_t held = std::min<sf_count_t>(wav->length_ - at - 8, 0xFFFFFFF0);
        if (size != 0 || held <= 0) return nullptr;
        wav->size_at_ = at + 4;
        for (int i = 0; i < 4; ++i)
          wav->size_[i] = static_cast<unsigned char>(held >> (8 * i));
        return std::fseek(wav->file_.get(), 0, SEEK_SET) == 0 ? std::move(wav) : nullptr;
      }
      at += 8 + static_cast<sf_count_t>(size) + (size & 1);
    }
    return nullptr;
  }
  explicit UnfinishedWav(Key) {}
  UnfinishedWav(const UnfinishedWav&) = delete;
  UnfinishedWav& operator=(const UnfinishedWav&) = delete;

  SNDFILE* open_sndfile(SF_INFO& info) { return sf_open_virtual(&io_, SFM_READ, &info, this); }

 private:
  struct FileCloser {
    void operator()(std::FILE* f) const noexcept { std::fclose(f); }
  };
  bool read_at(sf_count_t at, unsigned char* out, std::size_t n) {
    return fseeko(file_.get(), at, SEEK_SET) == 0 && std::fread(out, 1, n, file_.get()) == n;
  }
  static UnfinishedWav& self(void* user) { return *static_cast<UnfinishedWav*>(user); }
  static sf_count_t length(void* user) { return self(user).length_; }
  static sf_count_t seek(sf_count_t offset, int whence, void* user) {
    std::FILE* f = self(user).file_.get();
    return fseeko(f, offset, whence) == 0 ? ftello(f) : -1;
  }
  static sf_count_t tell(void* user) { return ftello(self(user).file_.get()); }
  static sf_count_t write(const void*, sf_count_t, void*) { return 0; }
  // The file's bytes, with the data chunk's size as the file holds it.
  static sf_count_t read(void* out, sf_count_t count, void* user) {
    UnfinishedWav& wav = self(user);
    std::FILE* f = wav.file_.get();
    const sf_count_t at = ftello(f);
    const auto got = static_cast<sf_count_t>(std::fread(out, 1, static_cast<std::size_t>(count), f));
    auto* bytes = static_cast<unsigned char*>(out);
    for (sf_count_t i = std::max(at, wav.size_at_); i < std::min(at + got, wav.size_at_ + 4); ++i)
      bytes[i - at] = wav.size_[i - wav.size_at_];
    return got;
  }
  std::unique_ptr<std::FILE, FileCloser> file_;
  sf_count_t length_ = 0, size_at_ = 0;
  unsigned char size_[4] = {};
  SF_VIRTUAL_IO io_{length, seek, read, write, tell};
};

// Without `with_confidence`, freq is empty unless the hop is tracked (the contract of `track`); with it,
// every estimate is printed and the confidence column says how far to trust it.
void print_point(const TrackPoint& p, bool with_confidence) {
  char freq[32] = "", snr[32] = "";
  if ((p.tracked || with_confidence) && std::isfinite(p.freq))
    std::snprintf(freq, sizeof freq, "%.3f", p.freq);
  if (std::isfinite(p.snr_db)) std::snprintf(snr, sizeof snr, "%.1f", p.snr_db);
  if (with_confidence)
    std::printf("%.4f,%s,%s,%.3f\n", p.t, freq, snr, p.confidence);
  else
    std::printf("%.4f,%s,%s\n", p.t, freq, snr);
}

// Prints what the tracker has output, the header with the first row (a file too short for one window is an
// error with nothing on stdout); `rows` counts the rows printed.
void print_outputs(SlidingDftTracker& tracker, bool with_confidence, std::size_t& rows) {
  TrackPoint p;
  while (tracker.pop(p)) {  // the outputs at once, for a live reader; the track printed is the decided one
  }
  while (tracker.pop_decided(p)) {
    if (rows++ == 0) std::printf(with_confidence ? "t,freq,snr_db,confidence\n" : "t,freq,snr_db\n");
    print_point(p, with_confidence);
  }
}

int run_track(const TrackOptions& o) {
  TrackerConfig config;
  parse_band(o.band, config);
  config.hop_s = o.hop_s;
  config.window_s = o.window_s;
  config.max_slew_hz_per_s = o.max_slew;
  config.decision_lag_s = o.decision_lag_s;
  config.require_harmonics = !o.any_line;
  config.history_s = 0.0;  // offline: no queries into the past

  SF_INFO info{};
  std::unique_ptr<UnfinishedWav> unfinished;  // outlives `file`, which reads through it
  std::unique_ptr<SNDFILE, SndfileCloser> file(sf_open(o.file.c_str(), SFM_READ, &info));
  if (!file) {
    // A file that is not there is said as fit says it; one that is no audio, with where a log goes. "-" is
    // standard input to libsndfile, and a path that cannot be looked up (ec set: EACCES, ELOOP, ...) is
    // no proof of absence: both keep libsndfile's own error.
    if (std::error_code ec; o.file != "-" && !std::filesystem::exists(o.file, ec) && !ec)
      throw UsageError(o.file + ": cannot open: " + std::strerror(ENOENT));
    if (std::error_code ec; std::filesystem::is_directory(o.file, ec))
      throw UsageError(o.file + ": is a directory (name a WAV recording in it)");
    const bool unrecognised = sf_error(nullptr) == SF_ERR_UNRECOGNISED_FORMAT;
    throw UsageError(o.file + ": cannot read audio: " + sf_strerror(nullptr) +
                     (unrecognised ? " (track reads a WAV recording; a CSV log of speed and rpm is for fit "
                                     "and replay)"
                                   : ""));
  }
  if (info.frames == 0 && (info.format & SF_FORMAT_TYPEMASK) == SF_FORMAT_WAV &&
      (unfinished = UnfinishedWav::open(o.file))) {
    info = SF_INFO{};
    file.reset(unfinished->open_sndfile(info));
    if (!file) throw UsageError(o.file + ": cannot read audio: " + sf_strerror(nullptr));
  }
  if (!readable_encoding(info.format))
    throw UsageError(o.file + ": unsupported sample encoding (PCM, float or G.711 expected)");
  bool streamed = false;
  if (long long declared = 0, actual = 0; truncated(file.get(), declared, actual, streamed))
    throw UsageError(o.file + ": truncated: the data chunk declares " + std::to_string(declared) +
                     " bytes, the file holds " + std::to_string(actual));
  if (streamed || unfinished)
    std::fprintf(stderr,
                 "gearpulse: warning: %s: the header gives no length (a streamed or interrupted recording): "
                 "reading the %lld frames the file holds\n",
                 o.file.c_str(), static_cast<long long>(info.frames));
  if (info.frames <= 0 || info.channels <= 0) throw UsageError(o.file + ": no audio frames");
  if (o.channel >= info.channels)
    throw UsageError(o.file + ": --channel " + std::to_string(o.channel) + " but the file has " +
                     std::to_string(info.channels) + " channel(s)");
  config.sample_rate_hz = info.samplerate;
  std::string error;
  auto tracker = SlidingDftTracker::create(config, error);
  // The band and the window are judged at the file's rate (the band against its Nyquist frequency): such a
  // refusal names the file and its rate; the others are the options' alone.
  if (!tracker) {
    const bool at_rate = error.starts_with("band") || error.starts_with("sample rate") ||
                         (error.starts_with("hop") && error.find(" Hz") != std::string::npos);
    throw UsageError(at_rate ? "the tracker options do not suit " + o.file + " (" +
                                   std::to_string(info.samplerate) + " Hz): " + error
                             : "tracker options refused: " + error);
  }

  constexpr sf_count_t kBlock = 4096;
  const auto channels = static_cast<std::size_t>(info.channels);
  std::vector<float> interleaved(static_cast<std::size_t>(kBlock) * channels);
  std::vector<float> mono(static_cast<std::size_t>(kBlock));
  sf_count_t total = 0;
  std::size_t rows = 0;
  for (;;) {
    const sf_count_t got = sf_readf_float(file.get(), interleaved.data(), kBlock);
    if (got <= 0) break;
    total += got;
    const std::size_t frames =
        extract_channel(std::span<const float>(interleaved.data(), static_cast<std::size_t>(got) * channels),
                        info.channels, o.channel, mono);
    // At most half the tracker's output queue of hops per push: at short hops a whole block holds more
    // hops than the queue, and the oldest were dropped (one row per hop is the contract).
    const std::size_t step = tracker->max_push_frames();
    for (std::size_t at = 0; at < frames; at += step) {
      tracker->push(std::span<const float>(mono.data() + at, std::min(step, frames - at)));
      print_outputs(*tracker, o.confidence, rows);
    }
  }
  tracker->finish();  // the hops held back for --decision-lag
  print_outputs(*tracker, o.confidence, rows);
  if (sf_error(file.get()) != SF_ERR_NO_ERROR)
    throw UsageError(o.file + ": read error after " + std::to_string(total) +
                     " frames: " + sf_strerror(file.get()));
  if (rows == 0) {
    char what[256];
    std::snprintf(what, sizeof what,
                  "%lld frames (%.4g s) hold no whole analysis window of %.3g s (a window starts on the hop "
                  "grid, after the band filter's run-in: a little more than one window is needed)",
                  static_cast<long long>(total), static_cast<double>(total) / info.samplerate, o.window_s);
    throw UsageError(o.file + ": " + what);
  }
  if (total < info.frames)
    throw UsageError(o.file + ": truncated: header announces " + std::to_string(info.frames) +
                     " frames, file holds " + std::to_string(total));
  std::fflush(stdout);
  return 0;
}

}  // namespace

void add_track(CLI::App& app, int& status) {
  auto options = std::make_shared<TrackOptions>();
  CLI::App* cmd =
      app.add_subcommand("track", "Print the engine-frequency track of a WAV recording (t,freq,snr_db)");
  cmd->add_option("--band", options->band, "search band of the fundamental, LO:HI in Hz")
      ->capture_default_str();
  cmd->add_option("--hop", options->hop_s, "time between outputs (s)")->capture_default_str();
  cmd->add_option("--window", options->window_s, "analysis window (s)")->capture_default_str();
  cmd->add_option("--channel", options->channel, "channel to use (0-based); default: mix all channels")
      ->check(number_in(0, 1023, true));
  cmd->add_option("--max-slew", options->max_slew, "fastest followed frequency change (Hz/s)")
      ->capture_default_str();
  cmd->add_option("--decision-lag", options->decision_lag_s,
                  "decide each hop's confidence with the windows of the next S seconds (0-2; the daemon's "
                  "tracker.decision_lag)")
      ->capture_default_str()
      ->check(number_in(0.0, 2.0));
  cmd->add_flag("--any-line", options->any_line, "also acquire lines without harmonics (pure-sine ripple)");
  cmd->add_flag("--confidence", options->confidence,
                "add a confidence column (probability the estimate is the engine) and print every estimate");
  cmd->add_option("FILE", options->file, "WAV recording (any rate, mono or multi-channel)")->required();
  cmd->callback([options, &status] { status = run_track(*options); });
}

}  // namespace gearpulse::cli
