// The ALSA capture PCM (AlsaCapture, drivers/alsa_capture.hpp): opening and configuring it (open_pcm,
// drivers/alsa_pcm.hpp), closing it, and the names of its formats, failed steps and recoveries.
#include "drivers/alsa_pcm.hpp"

#include <alsa/asoundlib.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <utility>

namespace gearpulse {
namespace {

snd_pcm_format_t to_alsa(PcmFormat f) noexcept {
  switch (f) {
    case PcmFormat::kS16:
      return SND_PCM_FORMAT_S16;
    case PcmFormat::kS32:
      return SND_PCM_FORMAT_S32;
    case PcmFormat::kFloat:
      return SND_PCM_FORMAT_FLOAT;
  }
  return SND_PCM_FORMAT_UNKNOWN;
}

}  // namespace

// open_pcm: see drivers/alsa_pcm.hpp.
int open_pcm(const AlsaCaptureConfig& c, PcmHandle& out, Negotiated& got, OpenFailure& failed) noexcept {
  snd_pcm_t* opened = nullptr;
  int err = ::snd_pcm_open(&opened, c.device.c_str(), SND_PCM_STREAM_CAPTURE, SND_PCM_NONBLOCK);
  if (err < 0) {
    failed = {AlsaStep::kOpen, "cannot open"};
    return err;
  }
  PcmHandle handle(opened);
  snd_pcm_t* const pcm = handle.get();
  auto bail = [&](const char* what, int e, AlsaStep step = AlsaStep::kHwParams) {
    failed = {step, what};
    return e;
  };
  snd_pcm_hw_params_t* hw = nullptr;
  snd_pcm_hw_params_alloca(&hw);
  if ((err = ::snd_pcm_hw_params_any(pcm, hw)) < 0) return bail("no hardware parameters", err);
  if ((err = ::snd_pcm_hw_params_set_access(pcm, hw, SND_PCM_ACCESS_RW_INTERLEAVED)) < 0)
    return bail("interleaved access refused", err);
  // The preferred format first, then the others.
  const PcmFormat order[] = {c.format, PcmFormat::kS16, PcmFormat::kS32, PcmFormat::kFloat};
  err = -EINVAL;
  for (const PcmFormat f : order) {
    if (::snd_pcm_hw_params_test_format(pcm, hw, to_alsa(f)) == 0) {
      err = ::snd_pcm_hw_params_set_format(pcm, hw, to_alsa(f));
      if (err == 0) {
        got.format = f;
        break;
      }
    }
  }
  if (err < 0) return bail("none of S16, S32, FLOAT is supported", err);
  unsigned channels = c.channels;
  if ((err = ::snd_pcm_hw_params_set_channels_near(pcm, hw, &channels)) < 0)
    return bail("channels refused", err);
  unsigned rate = c.rate;
  if ((err = ::snd_pcm_hw_params_set_rate_near(pcm, hw, &rate, nullptr)) < 0)
    return bail("rate refused", err);
  snd_pcm_uframes_t period = c.period_frames;
  if ((err = ::snd_pcm_hw_params_set_period_size_near(pcm, hw, &period, nullptr)) < 0)
    return bail("period size refused", err);
  snd_pcm_uframes_t buffer = period * std::max(2u, c.periods);
  if ((err = ::snd_pcm_hw_params_set_buffer_size_near(pcm, hw, &buffer)) < 0)
    return bail("buffer size refused", err);
  if ((err = ::snd_pcm_hw_params(pcm, hw)) < 0) return bail("hardware parameters refused", err);

  snd_pcm_sw_params_t* sw = nullptr;
  snd_pcm_sw_params_alloca(&sw);
  if ((err = ::snd_pcm_sw_params_current(pcm, sw)) < 0)
    return bail("no software parameters", err, AlsaStep::kSwParams);
  ::snd_pcm_sw_params_set_avail_min(pcm, sw, period);
  // Timestamps on CLOCK_MONOTONIC, the daemon's time base.
  ::snd_pcm_sw_params_set_tstamp_mode(pcm, sw, SND_PCM_TSTAMP_ENABLE);
  ::snd_pcm_sw_params_set_tstamp_type(pcm, sw, SND_PCM_TSTAMP_TYPE_MONOTONIC);
  if ((err = ::snd_pcm_sw_params(pcm, sw)) < 0)
    return bail("software parameters refused", err, AlsaStep::kSwParams);

  got.rate = rate;
  got.channels = channels;
  got.period = static_cast<unsigned>(period);
  out = std::move(handle);
  return 0;
}

void PcmClose::operator()(snd_pcm_t* pcm) const noexcept {
  ::snd_pcm_close(pcm);
}

AlsaRecovery recovery_for(int alsa_error) noexcept {
  switch (alsa_error) {
    case -EINTR:
    case -EAGAIN:
      return AlsaRecovery::kRetry;
    case -EPIPE:
      return AlsaRecovery::kRestart;
    case -ESTRPIPE:
      return AlsaRecovery::kResume;
    default:
      return AlsaRecovery::kReopen;
  }
}

const char* to_string(AlsaRecovery recovery) noexcept {
  switch (recovery) {
    case AlsaRecovery::kRetry:
      return "retry";
    case AlsaRecovery::kRestart:
      return "restart";
    case AlsaRecovery::kResume:
      return "resume";
    case AlsaRecovery::kReopen:
      return "reopen";
  }
  return "?";
}

const char* to_string(AlsaStep step) noexcept {
  switch (step) {
    case AlsaStep::kNone:
      return "";
    case AlsaStep::kOpen:
      return "open";
    case AlsaStep::kHwParams:
      return "hw-params";
    case AlsaStep::kSwParams:
      return "sw-params";
    case AlsaStep::kParamsChanged:
      return "params-changed";
    case AlsaStep::kPrepare:
      return "prepare";
    case AlsaStep::kStart:
      return "start";
    case AlsaStep::kWait:
      return "wait";
    case AlsaStep::kRead:
      return "read";
  }
  return "?";
}

std::uint64_t AlsaFailure::word() const noexcept {
  const auto code = static_cast<std::uint32_t>(error);  // two's complement: from_word() undoes it
  return static_cast<std::uint64_t>(code) | static_cast<std::uint64_t>(step) << 32;
}

AlsaFailure AlsaFailure::from_word(std::uint64_t word) noexcept {
  return {static_cast<AlsaStep>(static_cast<std::uint8_t>(word >> 32)),
          static_cast<std::int32_t>(static_cast<std::uint32_t>(word & 0xffff'ffffU))};
}

const char* to_string(PcmFormat format) noexcept {
  switch (format) {
    case PcmFormat::kS16:
      return "S16";
    case PcmFormat::kS32:
      return "S32";
    case PcmFormat::kFloat:
      return "FLOAT";
  }
  return "?";
}

}  // namespace gearpulse
