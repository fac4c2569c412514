#pragma once
// The sliding-DFT tracker's state and its constants, shared by the tracker's translation units (not part of
// the public API; core/sliding_dft_tracker.hpp says what the tracker does). What each file holds:
//   sliding_dft_tracker.cpp             the public API: configuration, input, outputs (with the fixed-lag
//                                       decision), at() and nearest()
//   sliding_dft_tracker_estimate.cpp    one window: its spectrum, the sub-bin estimate and its SNR
//   sliding_dft_tracker_candidates.cpp  the evidence of every candidate fundamental in one window
//   sliding_dft_tracker_hop.cpp         one hop: the filter's update, the estimate and its confidence, and
//                                       what is learned from it (fixed tones, half order, 3rd harmonic)
#include "core/decimating_input.hpp"
#include "core/sinusoid_fit.hpp"
#include "core/sliding_dft_tracker.hpp"
#include "core/sliding_dft_tracker_evidence.hpp"
#include "core/tone_map.hpp"
#include "core/track_model.hpp"
#include "core/track_outputs.hpp"
#include "core/window_spectrum.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <numbers>
#include <optional>
#include <vector>

namespace gearpulse {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = std::numbers::pi;
constexpr std::size_t kOutputQueue = 256;  // hops of output queued for the caller to pop

// Orders of the engine component scored and refined: half-order, fundamental, 2nd and 3rd harmonic.
constexpr int kOrders = 4;
constexpr double kOrder[kOrders] = {0.5, 1.0, 2.0, 3.0};
// Per-bin SNR of the fundamental assumed before a track gives its level, and the memory of the track's
// level (per hop). 3 is a -5 dB line's level (against the noise of the 150 Hz default band) in one bin of a
// 0.1 s Hann window: 10^-0.5 x 150 x T / 1.5. At the default 0.16 s such a line gives 5.1, but scaling the
// assumed level with the window lets an unconfirmed line weigh more before it is followed (tuning scenes at
// 0.16 s, -5 dB: coverage 58.9 -> 57.6 %, gross 0.65 -> 2.07 %), so it stays at 3 whatever the window.
constexpr double kDefaultRho = 3.0;
constexpr double kRhoMemory = 0.7;
// A window hides the engine's line (a gear shift's smear, a line masked by another or faded below the
// evidence's level prior) with this probability when the line stands at the default level; a louder line
// is hidden less often, by the square of its per-bin SNR over the default (a loud line that vanishes has
// stopped or moved, and the track lets it go as fast as without the allowance). Otherwise a track at
// -5 dB passes to "engine absent" on the many windows where its line fades and restarts anywhere, often
// on twice the engine. Chosen on the generated scenes' tuning set (see docs/algorithms/tracker-method.md).
constexpr double kHiddenShare = 0.3;
// The candidates' shoulder term (a state on the shoulder of a stronger peak within one resolution bin is
// not where the line is) compares amplitudes (sqrt of normalised power) against unit-order noise and, on a
// loud line, against this share of its amplitude: a window's line is no stationary sinusoid centred on a
// fine bin (it sweeps, changes its level within the window and lies between bins), so the states place a
// line to about a quarter of a resolution bin (where a Hann main lobe is 4 % down in amplitude) and the
// sub-bin fit does the rest. Against noise alone the term grows with the line's level: a line 30-50 dB over
// the noise whose top a sweep has flattened loses several nats on every state, and the track passes to
// "engine absent" while the line stands clear.
constexpr double kShoulderShape = 0.05;
// Mean normalised power from which a learned tone is fitted along with the engine's orders.
constexpr double kToneFitLevel = ToneMap::kFitLevel;
constexpr double kToneCandidate = 0.05;  // probability from which the estimate's line is a candidate
// The estimate holds its line's peak when its power is within 3 dB of the peak's, or within the noise of it
// (sqrt of normalised power; the shoulder of a line one resolution bin away is 6 dB down).
constexpr double kToneCandidateMismatch = 2.0;
// Whether this signal carries a half order is learned from confident hops whose fundamental stands this
// far over the noise (per bin), so that a half order at the prior's lowest ratio (0.03) would show over a
// floor alike, or, while the track is not confident, from a harmonic pair whose two lines do
// (learn_orders_from_pair()); over this time (s). Until then HarmonicEvidence::kOrderAbsent holds.
constexpr double kHalfObserveRho = 100.0;
constexpr double kHalfMemoryS = 1.0;
constexpr double kHalfObserveRight = 0.95;
// The 3rd harmonic's level against the fundamental is a property of the engine and its wiring (the shape of
// its firing pulse) and changes slowly: it is learned (dB, a mean and a spread over kThirdMemoryS) from the
// hops on which the half order's presence is learned (a confident estimate, a fundamental 20 dB over the
// noise per bin, so that a 3rd harmonic at -20 dB shows over a floor alike; a weaker one is read at that
// floor). The 3rd harmonic's level prior is then a mixture: the learned level (normal in dB, its spread
// widened by kThirdSpreadFloorDb) with weight n / (n + kThirdPriorS / hop) for n hops learned (exponentially
// forgotten), the fixed prior with the rest, so that the fixed prior is worth kThirdPriorS of such hops.
// The 2nd harmonic's level swings with load and the half order's presence is learned on its own (see
// docs/algorithms/tracker-method.md). Chosen on the generated scenes' tuning set.
constexpr double kThirdMemoryS = 10.0;
constexpr double kThirdPriorS = 0.5;
constexpr double kThirdSpreadFloorDb = 2.0;
// A bin's long-run level below the noise floor scales the floor down to its noise (ToneMap::background())
// while the track's line stands less than 30 dB over the noise per bin. A louder line leaks through the Hann
// window's sidelobes (31 dB down, falling 18 dB an octave) over much of a floor's block: the floor is then
// the leakage's, not a biased noise level, and scaled down there it lets a clean line's 2nd harmonic
// outweigh the line (docs/algorithms/tracker-method.md, "A floor read over the noise").
constexpr double kLeakRho = 1000.0;
// Memory (per hop) of the band's noise level behind the reported SNR.
constexpr double kNoiseMemory = 0.9;
// Uncertainty (Hz) of the track's prediction one hop ahead (about the slew of a ramping engine over a
// 0.1 s hop), the prior of the sub-bin estimate.
constexpr double kPredictionHz = 2.0;
// A hop is "tracked" when its estimate is right (within 5 % of the engine's fundamental) with probability
// 0.8 or more: the engine speed and the training pairs are built on it, so it must be right nearly every
// time; the probability itself is reported as the confidence.
constexpr double kTrackedConfidence = 0.8;
// at() keeps to the nearest hop output within this time.
constexpr double kCoastS = 0.5;
constexpr int kZeroPad = 8;

struct SlidingDftTracker::Impl {
  TrackerConfig cfg;
  double fs = 0.0;
  DecimatingInput input;           // the input frames and the decimator that reads windows from them
  double fd = 0.0;                 // decimated rate
  double harmonic_limit_hz = 0.0;  // highest frequency the decimated signal represents faithfully
  int n_win = 0;                   // decimated samples per window (odd)
  int nfft = 0;
  double df = 0.0;             // fine bin width (Hz)
  std::int64_t half_span = 0;  // input frames from a window centre to its first/last used frame
  std::int64_t hop_frames = 1;

  double t0 = 0.0;  // time of frame 0
  std::uint64_t next_centre = 0;

  // Per-hop scratch (sized at construction).
  std::vector<double> dec;                 // decimated window, detrended and tapered
  std::vector<double> raw;                 // decimated window as filtered (for the least-squares fit)
  std::optional<WindowSpectrum> spectrum;  // the window's power and noise floor per fine bin
  int k_lo = 0, k_hi = 0;                  // band, fine bins
  int s_lo = 0;                            // lowest state, fine bin (half the band's lower edge)
  int noise_lo = 1, noise_hi = 1;          // fine bins used for the noise floor
  const HarmonicEvidence& evidence = HarmonicEvidence::shared();
  double temper = 1.0;        // overlapping windows are not independent evidence
  double half_present = 1.0;  // share of clear confident hops that showed a half order (see kHalfMemoryS)
  double half_keep = 1.0;     // per hop
  // The 3rd harmonic's learned level ratio to the fundamental (see kThirdMemoryS): weight of the hops
  // learned, the ratio's mean and variance (dB).
  double third_n = 0.0, third_mean_db = 0.0, third_var_db = 0.0;
  double third_keep = 1.0;   // per hop
  double third_prior = 1.0;  // hops the fixed prior is worth
  int lobe = 1;              // fine bins per resolution bin (1 / window)

  // The track over hops: candidates are the fine bins s_lo..k_hi (from half the band's lower edge, so
  // that an idling engine is followed below the band and its 2nd harmonic is not taken for it).
  std::optional<TrackModel> track;
  std::vector<double> at_loglik;  // at()'s candidates, apart from the track's
  double rho_track = kDefaultRho;
  bool floor_is_noise = true;    // rho_track below kLeakRho (this hop)
  std::optional<ToneMap> tones;  // fixed tones of other equipment, counted as background

  TrackOutputs outputs;  // each hop at once, and the history at() and nearest() look back on
  // The fixed-lag decision (TrackerConfig::decision_lag_s): the decided outputs (their queue; its history
  // is not read), and the latest hops' outputs, held back until `lag` more hops have been analysed (a ring
  // of lag + 1, oldest first from lagged_head).
  TrackOutputs decided;
  int lag = 0;
  std::vector<TrackPoint> lagged;
  std::size_t lagged_head = 0, lagged_size = 0;
  [[nodiscard]] const TrackPoint& lagged_at(std::size_t i) const noexcept {
    return lagged[(lagged_head + i) % lagged.size()];
  }
  // Queues a hop's output at once, and as decided the one `lag` hops older, its confidence decided with the
  // hops after it (the history takes that confidence too).
  void deliver(const TrackPoint& p) noexcept;
  void release_lagged() noexcept;  // queues every held output as decided as it stands

  struct Evidence {
    double freq = kNaN;
    double snr[kOrders] = {0, 0, 0, 0};  // per-bin SNR (linear) at order x freq; 0 where unavailable
    bool available[kOrders] = {false, false, false, false};
    double ladder_excess = 0.0;
    double snr_db = kNaN;
    double log_likelihood = -INFINITY;  // of the refined frequency, with the track's prior if any
    double noise_level = kNaN;          // noise variance per decimated sample in the band, this window
    double fundamental_amp2 = 0.0;      // squared amplitude of the fitted fundamental
  };

  explicit Impl(const TrackerConfig& c);
  [[nodiscard]] const std::vector<double>& power() const noexcept { return spectrum->power(); }
  [[nodiscard]] const std::vector<double>& noise() const noexcept { return spectrum->noise(); }

  [[nodiscard]] double time_of(double frame) const noexcept { return t0 + frame / fs; }
  bool analyse(std::uint64_t centre) noexcept;
  [[nodiscard]] double noise_at(double fine_bin) const noexcept;
  // Normalised power of a fine bin over its background (ToneMap::background()), and a floor read over the
  // bin's noise scaled back to it while the floor is the noise's (floor_is_noise).
  [[nodiscard]] double z_at(std::size_t k) const noexcept {
    const double b = tones->background(k);
    return power()[k] / (noise()[k] * (b < 1.0 && !floor_is_noise ? 1.0 : b));
  }
  // The floor of fine bin a over that of fine bin b: carries a line's per-bin SNR at a to the SNR at b of a
  // line of the same power.
  [[nodiscard]] double floor_ratio(std::size_t a, std::size_t b) const noexcept {
    const double na = noise()[a], nb = noise()[b];
    return na > 0.0 && nb > 0.0 ? na / nb : 1.0;
  }
  void learn_tones(double freq, double right) noexcept;
  // `overrun`, when given, gets what a line on the overrun adds to it (HarmonicEvidence::second_overrun()),
  // `power` what a line under power adds (HarmonicEvidence::second_power()).
  void candidate_likelihoods(std::vector<double>& out, std::vector<double>* overrun = nullptr,
                             std::vector<double>* power = nullptr) const noexcept;
  // Log odds by which root f, for the state at fine bin k whose line has per-bin SNR rho_line, falls short
  // of its prior among the judged roots f / 4, f / 2 and f / 3 of a comb of which it would be the 4th, 2nd
  // or 3rd harmonic.
  [[nodiscard]] double comb_root_penalty(int k, double rho_line) const noexcept;
  void learn_orders(const Evidence& ev, double right) noexcept;
  void learn_orders_from_pair() noexcept;
  void add_half(double f1, double z_half) noexcept;
  void add_third_level(double rho1, double z3, std::size_t k1, std::size_t b) noexcept;
  void reset_track() noexcept;
  [[nodiscard]] double peak_near(int k, int reach) const noexcept;
  [[nodiscard]] double harmonic_peak_near(int k, int reach) const noexcept;
  [[nodiscard]] Evidence refine(double f0, double predicted = kNaN) noexcept;
  // Fundamental power over the band's noise power (the generator's definition), in dB. `learn`: the
  // window is the next hop's, whose noise level joins the average.
  [[nodiscard]] double snr_db(const Evidence& ev, bool learn) noexcept;
  // Least-squares model of a window: level, slope, a sinusoid per order and one for a learned fixed tone
  // next to the fundamental (slot kOrders), which would otherwise pull the fit.
  static constexpr int kSlots = kOrders + 1;
  static_assert(kSlots == SinusoidFit::kMaxSines);
  using Fit = SinusoidFit::Result;
  SinusoidFit sines{1, 1.0};
  double nuisance_hz = kNaN;  // the learned tone fitted along, for the current refine()
  double log_noise = kNaN;    // log of the band's noise variance per sample, averaged over hops
  [[nodiscard]] double slot_hz(int o, double f) const noexcept {
    return o < kOrders ? kOrder[o] * f : nuisance_hz;
  }
  [[nodiscard]] double harmonic_fit(double f, const bool* use, Fit* fit) const noexcept;
  [[nodiscard]] double sweep_mismatch(double f) const noexcept;
  [[nodiscard]] double residual_noise_level(double f, const Fit& fit) noexcept;
  TrackPoint process_hop(std::uint64_t centre) noexcept;
};

}  // namespace gearpulse
