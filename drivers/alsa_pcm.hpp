#pragma once
// Opening and configuring an ALSA capture PCM (alsa_pcm.cpp), for AlsaCapture (alsa_capture.cpp), which
// opens its device in its constructor and reopens a lost one on its thread.
#include "drivers/alsa_capture.hpp"

namespace gearpulse {

// What the device agreed to.
struct Negotiated {
  unsigned rate = 0;
  unsigned channels = 0;
  PcmFormat format = PcmFormat::kS16;
  unsigned period = 0;
};

// Why an open failed: the step (for status) and what was refused in it (for the constructor's message).
struct OpenFailure {
  AlsaStep step = AlsaStep::kNone;
  const char* what = "";
};

// Opens and configures the PCM into `out`; on failure returns the negative ALSA error and in `failed`
// the step that failed (a PCM opened on the way is closed: a device left open would be busy for every
// later attempt). Builds no string: the capture thread reopens a lost device with it.
int open_pcm(const AlsaCaptureConfig& c, PcmHandle& out, Negotiated& got, OpenFailure& failed) noexcept;

}  // namespace gearpulse
