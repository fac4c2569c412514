// The tracker's public API: the configuration's checks, the input and the hop schedule, the outputs, and
// the estimate at a given time (at()). One hop's work is in sliding_dft_tracker_hop.cpp.
#include "core/sliding_dft_tracker.hpp"

#include "core/sliding_dft_tracker_impl.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace gearpulse {
namespace {

std::size_t next_pow2(std::size_t n) {
  std::size_t p = 1;
  while (p < n)
    p <<= 1;
  return p;
}

std::string format(const char* fmt, double a, double b = 0.0, double c = 0.0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, a, b, c);
  return buf;
}

}  // namespace

std::size_t extract_channel(std::span<const float> interleaved, int channels, int channel,
                            std::span<float> out) noexcept {
  if (channels <= 0 || channel >= channels) return 0;
  const std::size_t frames = std::min(out.size(), interleaved.size() / static_cast<std::size_t>(channels));
  const auto ch = static_cast<std::size_t>(channels);
  for (std::size_t i = 0; i < frames; ++i) {
    const float* f = interleaved.data() + i * ch;
    if (channel >= 0) {
      out[i] = f[channel];
    } else {
      double sum = 0.0;
      for (std::size_t c = 0; c < ch; ++c)
        sum += f[c];
      out[i] = static_cast<float>(sum / static_cast<double>(ch));
    }
  }
  return frames;
}

SlidingDftTracker::Impl::Impl(const TrackerConfig& c)
    : cfg(c),
      fs(c.sample_rate_hz),
      input(c.sample_rate_hz, 3.0 * c.band_hi_hz),  // up to the highest scored harmonic
      outputs(kOutputQueue,
              std::max<std::size_t>(
                  8, static_cast<std::size_t>(std::ceil(c.history_s / std::max(c.hop_s, 1e-3))) + 2)),
      decided(kOutputQueue, 1) {
  fd = input.rate_hz();
  harmonic_limit_hz = input.limit_hz();
  n_win = static_cast<int>(std::lround(cfg.window_s * fd));
  if (n_win % 2 == 0) ++n_win;
  nfft = static_cast<int>(next_pow2(static_cast<std::size_t>(kZeroPad * n_win)));
  sines = SinusoidFit(n_win, fd);
  df = fd / nfft;
  half_span = static_cast<std::int64_t>((n_win - 1) / 2) * input.factor() +
              static_cast<std::int64_t>(input.taps() / 2);
  hop_frames = std::max<std::int64_t>(1, std::llround(cfg.hop_s * fs));

  const auto history_frames = static_cast<std::size_t>(std::ceil(cfg.history_s * fs));
  input.reserve(history_frames + 2 * static_cast<std::size_t>(half_span) +
                static_cast<std::size_t>(hop_frames) + 16);

  dec.resize(static_cast<std::size_t>(n_win));
  raw.resize(static_cast<std::size_t>(n_win));
  const auto bins = static_cast<std::size_t>(nfft / 2 + 1);
  k_lo = static_cast<int>(std::ceil(cfg.band_lo_hz / df));
  k_hi = static_cast<int>(std::floor(cfg.band_hi_hz / df));
  noise_lo = std::max(1, static_cast<int>(std::floor(0.5 * cfg.band_lo_hz / df)));
  noise_hi = std::min(static_cast<int>(bins) - 2, static_cast<int>(std::ceil(harmonic_limit_hz / df)));
  s_lo = std::max(noise_lo, static_cast<int>(std::ceil(0.5 * cfg.band_lo_hz / df)));
  spectrum.emplace(n_win, nfft, noise_lo, noise_hi);
  const auto states = static_cast<std::size_t>(k_hi - s_lo + 1);
  at_loglik.assign(states, 0.0);
  temper = std::min(1.0, cfg.hop_s / cfg.window_s);
  half_keep = std::exp(-cfg.hop_s / kHalfMemoryS);
  third_keep = std::exp(-cfg.hop_s / kThirdMemoryS);
  third_prior = kThirdPriorS / cfg.hop_s;
  lobe = std::max(1, nfft / n_win);
  track.emplace(cfg, s_lo, k_hi, df, lobe);
  tones.emplace(bins, noise_lo, noise_hi, lobe, df, cfg.hop_s);
  lag = static_cast<int>(std::lround(cfg.decision_lag_s / cfg.hop_s));
  lagged.assign(static_cast<std::size_t>(lag) + 1, TrackPoint{});
  reset_track();
}

// An engine's line is continuous: when the estimates of the `lag` hops after this one continue its
// estimate, each within the slew of the one before (the gate of the track's drift, TrackModel::observe()),
// and the last of them is more confident, the engine was on this hop's line with the confidence
// the later windows give the line they follow. The estimate stays; only its confidence is decided later.
// After a gear shift at -5 dB the new line's windows give about 1.2 nats a hop, and the posterior reaches
// 0.8 on a line whose estimates were right for a second or two before (docs/tracker.md, "What limits it").
void SlidingDftTracker::Impl::deliver(const TrackPoint& p) noexcept {
  outputs.emit(p);
  if (lag == 0) {
    decided.emit(p);
    return;
  }
  lagged[(lagged_head + lagged_size) % lagged.size()] = p;
  if (++lagged_size < lagged.size()) return;
  TrackPoint& first = lagged[lagged_head];
  const double gate = cfg.max_slew_hz_per_s * cfg.hop_s + 2.0 * df;
  bool continued = true;
  for (std::size_t i = 0; i + 1 < lagged_size && continued; ++i) {
    const double a = lagged_at(i).freq, b = lagged_at(i + 1).freq;
    continued = std::isfinite(a) && std::isfinite(b) && std::abs(b - a) <= gate;
  }
  if (const TrackPoint& last = lagged_at(lagged_size - 1); continued && last.confidence > first.confidence) {
    first.confidence = last.confidence;
    first.tracked = last.tracked;
    outputs.revise(first);
  }
  decided.emit(first);
  lagged_head = (lagged_head + 1) % lagged.size();
  --lagged_size;
}

void SlidingDftTracker::Impl::release_lagged() noexcept {
  for (std::size_t i = 0; i < lagged_size; ++i)
    decided.emit(lagged_at(i));
  lagged_head = lagged_size = 0;
}

// ---- public ----

std::string SlidingDftTracker::validate(const TrackerConfig& c) {
  const auto finite = [](double v) { return std::isfinite(v); };
  if (!finite(c.sample_rate_hz) || c.sample_rate_hz <= 0)
    return format("sample rate %g Hz is not a positive number", c.sample_rate_hz);
  if (!finite(c.band_lo_hz) || !finite(c.band_hi_hz) || c.band_lo_hz <= 0 || c.band_hi_hz <= c.band_lo_hz)
    return format("band %g:%g Hz is not a positive, increasing range", c.band_lo_hz, c.band_hi_hz);
  if (c.band_hi_hz >= 0.5 * c.sample_rate_hz)
    return format("band upper edge %g Hz is outside Nyquist (%g Hz at %g Hz sampling)", c.band_hi_hz,
                  0.5 * c.sample_rate_hz, c.sample_rate_hz);
  if (c.sample_rate_hz < 2.5 * c.band_hi_hz)
    return format("sample rate %g Hz is too low for a band up to %g Hz (needs at least %g Hz)",
                  c.sample_rate_hz, c.band_hi_hz, 2.5 * c.band_hi_hz);
  if (c.sample_rate_hz > 768000) return format("sample rate %g Hz is above 768000 Hz", c.sample_rate_hz);
  if (!finite(c.window_s) || c.window_s <= 0 || c.window_s > 2.0)
    return format("window %g s is outside (0, 2] s", c.window_s);
  if (c.window_s * c.band_lo_hz < 4.0)
    return format("window %g s is too short for the band: it must hold 4 periods of %g Hz (%g s)", c.window_s,
                  c.band_lo_hz, 4.0 / c.band_lo_hz);
  if (!finite(c.hop_s) || c.hop_s <= 0 || c.hop_s > 60.0)
    return format("hop %g s is outside (0, 60] s", c.hop_s);
  if (c.hop_s * c.sample_rate_hz < 1.0)
    return format("hop %g s is shorter than one frame at %g Hz", c.hop_s, c.sample_rate_hz);
  if (c.hop_s > 4.0 * c.window_s)
    return format("hop %g s is more than 4 windows (%g s): the audio between windows would be ignored",
                  c.hop_s, 4.0 * c.window_s);
  // No engine's frequency changes by more than some hundreds of Hz per second; the bound keeps the gates
  // (in bins) far from integer overflow.
  constexpr double kMaxSlew = 1e5;  // Hz/s
  if (!finite(c.max_slew_hz_per_s) || c.max_slew_hz_per_s < 0 || c.max_slew_hz_per_s > kMaxSlew)
    return format("max slew %g Hz/s is outside [0, %g] Hz/s", c.max_slew_hz_per_s, kMaxSlew);
  if (!finite(c.shift_slew_hz_per_s) || c.shift_slew_hz_per_s < 0 || c.shift_slew_hz_per_s > kMaxSlew)
    return format("shift slew %g Hz/s is outside [0, %g] Hz/s", c.shift_slew_hz_per_s, kMaxSlew);
  if (!finite(c.history_s) || c.history_s < 0 || c.history_s > 60)
    return format("history %g s is outside [0, 60] s", c.history_s);
  // A decision later than a couple of seconds helps no engine line (the posterior is sure of a line a
  // second or two after a shift) and would hold a queue of outputs back.
  if (!finite(c.decision_lag_s) || c.decision_lag_s < 0 || c.decision_lag_s > 2.0)
    return format("decision lag %g s is outside [0, 2] s", c.decision_lag_s);
  // The lagged outputs are queued at once at a hole or the stream's end, after at most half a queue of hops
  // pushed (max_push_frames()): they must fit in the rest of the queue, or outputs would be dropped.
  if (std::lround(c.decision_lag_s / c.hop_s) > static_cast<long>(kOutputQueue / 4))
    return format("decision lag %g s is more than %g hops of %g s", c.decision_lag_s,
                  static_cast<double>(kOutputQueue / 4), c.hop_s);
  return {};
}

std::unique_ptr<SlidingDftTracker> SlidingDftTracker::create(const TrackerConfig& config,
                                                             std::string& error) {
  error = validate(config);
  if (!error.empty()) return nullptr;
  try {
    return std::make_unique<SlidingDftTracker>(config);
  } catch (const std::exception& e) {
    error = e.what();
    return nullptr;
  }
}

SlidingDftTracker::SlidingDftTracker(const TrackerConfig& config) {
  if (std::string error = validate(config); !error.empty()) throw std::invalid_argument(error);
  impl_ = std::make_unique<Impl>(config);
  start(0.0);
}

SlidingDftTracker::~SlidingDftTracker() = default;

void SlidingDftTracker::start(double t0) noexcept {
  Impl& s = *impl_;
  s.t0 = t0;
  s.input.clear();
  const auto first_hop = (s.half_span + s.hop_frames - 1) / s.hop_frames;
  s.next_centre = static_cast<std::uint64_t>(first_hop * s.hop_frames);
  s.reset_track();
  s.tones->reset();
  s.half_present = 1.0;  // the half order is the source's: learned again from the new stream
  s.third_n = s.third_mean_db = s.third_var_db = 0.0;  // so is the 3rd harmonic's level
  s.log_noise = kNaN;
  s.outputs.clear();
  s.decided.clear();
  s.lagged_head = s.lagged_size = 0;
}

void SlidingDftTracker::retime(double t_next) noexcept {
  impl_->t0 = t_next - static_cast<double>(impl_->input.received()) / impl_->fs;
}

void SlidingDftTracker::skip(std::uint64_t frames) noexcept {
  Impl& s = *impl_;
  if (frames == 0) return;
  s.input.skip(frames);
  s.release_lagged();
  s.reset_track();
  // Hops whose windows overlap the hole give no output; resume on the hop grid after it.
  const auto h = static_cast<std::uint64_t>(s.hop_frames);
  const std::uint64_t min_centre = s.input.valid_from() + static_cast<std::uint64_t>(s.half_span);
  if (s.next_centre < min_centre) s.next_centre = (min_centre + h - 1) / h * h;
}

void SlidingDftTracker::push(std::span<const float> frames) noexcept {
  Impl& s = *impl_;
  std::size_t i = 0;
  while (i < frames.size()) {
    const std::uint64_t needed = s.next_centre + static_cast<std::uint64_t>(s.half_span) + 1;
    while (i < frames.size() && s.input.received() < needed)
      s.input.write(frames[i++]);
    if (s.input.received() >= needed) {
      s.deliver(s.process_hop(s.next_centre));
      s.next_centre += static_cast<std::uint64_t>(s.hop_frames);
    }
  }
}

void SlidingDftTracker::finish() noexcept {
  impl_->release_lagged();
}

bool SlidingDftTracker::pop(TrackPoint& out) noexcept {
  return impl_->outputs.pop(out);
}

bool SlidingDftTracker::pop_decided(TrackPoint& out) noexcept {
  return impl_->decided.pop(out);
}

TrackPoint SlidingDftTracker::at(double t) noexcept {
  Impl& s = *impl_;
  TrackPoint out;
  out.t = t;
  const double pos = (t - s.t0) * s.fs;
  if (!std::isfinite(pos)) return out;
  const double c = std::round(pos);
  const auto hs = static_cast<double>(s.half_span);
  const auto received = static_cast<double>(s.input.received());
  const double oldest = std::max(static_cast<double>(s.input.valid_from()),
                                 received - static_cast<double>(s.input.capacity()) + 1.0);
  if (c - hs < oldest || c + hs >= received) return out;
  const auto centre = static_cast<std::uint64_t>(c);
  out.t = s.time_of(c);
  // Prior: the nearest hop output with an estimate, within the coast time; this window's estimate is
  // the best candidate within the slew gate around it, and inherits its confidence.
  TrackPoint prior;
  double prior_dt = 1e9;
  for (std::size_t k = 0; k < s.outputs.held(); ++k) {
    const TrackPoint& h = s.outputs.recent(k);
    if (std::isfinite(h.freq) && std::abs(h.t - out.t) < prior_dt) {
      prior_dt = std::abs(h.t - out.t);
      prior = h;
    }
  }
  if (!std::isfinite(prior.freq) || prior_dt > kCoastS || !s.analyse(centre)) return out;
  const double gate = s.cfg.max_slew_hz_per_s * prior_dt + 2.0 * s.df + 1.0;
  const int lo = std::max(s.s_lo, static_cast<int>(std::floor((prior.freq - gate) / s.df)));
  const int hi = std::min(s.k_hi, static_cast<int>(std::ceil((prior.freq + gate) / s.df)));
  if (lo > hi) return out;
  s.candidate_likelihoods(s.at_loglik);  // the track state stays as the hops left it
  int best = lo;
  for (int k = lo; k <= hi; ++k)
    if (s.at_loglik[static_cast<std::size_t>(k - s.s_lo)] >
        s.at_loglik[static_cast<std::size_t>(best - s.s_lo)])
      best = k;
  const Impl::Evidence ev = s.refine(s.harmonic_peak_near(best, s.lobe) * s.df);
  out.snr_db = ev.snr_db;
  if (std::abs(ev.freq - prior.freq) <= gate && ev.freq >= s.cfg.band_lo_hz - s.df &&
      ev.freq <= s.cfg.band_hi_hz + s.df) {
    out.freq = ev.freq;
    out.confidence = prior.confidence;
    out.tracked = prior.tracked;
  }
  return out;
}

TrackPoint SlidingDftTracker::nearest(double t) const noexcept {
  const Impl& s = *impl_;
  TrackPoint best;
  best.t = t;
  double best_dt = 0.5 * s.cfg.hop_s + 1e-9;
  for (std::size_t k = 0; k < s.outputs.held(); ++k) {
    const TrackPoint& h = s.outputs.recent(k);
    if (std::abs(h.t - t) <= best_dt) {
      best_dt = std::abs(h.t - t);
      best = h;
    }
  }
  return best;
}

double SlidingDftTracker::latest_time() const noexcept {
  const Impl& s = *impl_;
  const auto last = static_cast<std::int64_t>(s.input.received()) - 1 - s.half_span;
  if (last < static_cast<std::int64_t>(s.input.valid_from()) + s.half_span) return kNaN;
  return s.time_of(static_cast<double>(last));
}

int SlidingDftTracker::decision_lag_hops() const noexcept {
  return impl_->lag;
}

const TrackerConfig& SlidingDftTracker::config() const noexcept {
  return impl_->cfg;
}
double SlidingDftTracker::decimated_rate_hz() const noexcept {
  return impl_->fd;
}
std::size_t SlidingDftTracker::queue_capacity() const noexcept {
  return impl_->outputs.queue_capacity();
}
std::size_t SlidingDftTracker::max_push_frames() const noexcept {
  return std::max<std::size_t>(
      1, impl_->outputs.queue_capacity() / 2 * static_cast<std::size_t>(impl_->hop_frames));
}
std::size_t SlidingDftTracker::history_size() const noexcept {
  return impl_->outputs.history_capacity();
}
std::uint64_t SlidingDftTracker::dropped_outputs() const noexcept {
  return impl_->outputs.dropped();
}

}  // namespace gearpulse
