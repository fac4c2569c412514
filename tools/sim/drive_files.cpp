#include "tools/sim/drive_files.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <stdexcept>

namespace gearpulse::sim {
namespace {

struct FileCloser {
  void operator()(std::FILE* f) const noexcept { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

File open_for_writing(const std::string& path, const char* mode) {
  File f(std::fopen(path.c_str(), mode));
  if (!f) throw std::runtime_error(path + ": " + std::strerror(errno));
  return f;
}

void finish(File f, const std::string& path) {
  const bool bad = std::ferror(f.get()) != 0;
  if (std::fclose(f.release()) != 0 || bad) throw std::runtime_error(path + ": write error");
}

double parse_seconds(std::string_view text, std::string_view whole) {
  double value = 0.0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc{} || end != text.data() + text.size() || !std::isfinite(value) || value < 0.0) {
    throw std::invalid_argument("outage '" + std::string(whole) + "': expected START:LEN in seconds");
  }
  return value;
}

void put_le(std::uint8_t* p, std::uint32_t v, int bytes) {
  for (int i = 0; i < bytes; ++i)
    p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

void put_cell(std::FILE* f, double v) {
  if (std::isfinite(v)) std::fprintf(f, "%.4f", v);
}

}  // namespace

Outage parse_outage(std::string_view text) {
  const auto colon = text.find(':');
  if (colon == std::string_view::npos) {
    throw std::invalid_argument("outage '" + std::string(text) + "': expected START:LEN in seconds");
  }
  return {parse_seconds(text.substr(0, colon), text), parse_seconds(text.substr(colon + 1), text)};
}

std::vector<std::int16_t> to_s16(std::span<const float> signal) {
  std::vector<std::int16_t> pcm(signal.size());
  std::transform(signal.begin(), signal.end(), pcm.begin(), [](float x) {
    const float scaled = std::round(std::clamp(x, -1.0f, 1.0f) * 32767.0f);
    return static_cast<std::int16_t>(scaled);
  });
  return pcm;
}

void write_raw_s16(const std::string& path, std::span<const std::int16_t> pcm) {
  File f = open_for_writing(path, "wb");
  // Raw S16_LE as the ALSA file plugin hands it to the capture; this host is little endian.
  std::fwrite(pcm.data(), sizeof(std::int16_t), pcm.size(), f.get());
  finish(std::move(f), path);
}

void write_wav_s16(const std::string& path, std::span<const std::int16_t> pcm, int rate) {
  const auto data_bytes = static_cast<std::uint32_t>(pcm.size() * sizeof(std::int16_t));
  std::uint8_t header[44] = {};
  std::memcpy(header, "RIFF", 4);
  put_le(header + 4, 36 + data_bytes, 4);
  std::memcpy(header + 8, "WAVEfmt ", 8);
  put_le(header + 16, 16, 4);  // fmt chunk size
  put_le(header + 20, 1, 2);   // PCM
  put_le(header + 22, 1, 2);   // mono
  put_le(header + 24, static_cast<std::uint32_t>(rate), 4);
  put_le(header + 28, static_cast<std::uint32_t>(rate) * 2, 4);  // byte rate
  put_le(header + 32, 2, 2);                                     // block align
  put_le(header + 34, 16, 2);                                    // bits per sample
  std::memcpy(header + 36, "data", 4);
  put_le(header + 40, data_bytes, 4);
  File f = open_for_writing(path, "wb");
  std::fwrite(header, 1, sizeof header, f.get());
  std::fwrite(pcm.data(), sizeof(std::int16_t), pcm.size(), f.get());
  finish(std::move(f), path);
}

void write_truth_csv(const std::string& path, std::span<const TruthRow> rows) {
  File f = open_for_writing(path, "w");
  std::fputs("t,speed,freq,gear\n", f.get());
  for (const TruthRow& r : rows)
    std::fprintf(f.get(), "%.3f,%.4f,%.4f,%d\n", r.t, r.speed, r.freq, r.gear);
  finish(std::move(f), path);
}

void write_samples_csv(const std::string& path, std::span<const SampleRow> rows) {
  File f = open_for_writing(path, "w");
  std::fputs("t,speed,freq\n", f.get());
  for (const SampleRow& r : rows) {
    std::fprintf(f.get(), "%.3f,", r.t);
    put_cell(f.get(), r.speed);
    std::fputc(',', f.get());
    put_cell(f.get(), r.freq);
    std::fputc('\n', f.get());
  }
  finish(std::move(f), path);
}

void write_lines(const std::string& path, std::span<const std::string> lines) {
  File f = open_for_writing(path, "w");
  for (const std::string& line : lines) {
    std::fputs(line.c_str(), f.get());
    std::fputc('\n', f.get());
  }
  finish(std::move(f), path);
}

double distance_m(std::span<const TruthRow> rows) noexcept {
  double d = 0.0;
  for (std::size_t i = 1; i < rows.size(); ++i) {
    d += 0.5 * (rows[i].speed + rows[i - 1].speed) * (rows[i].t - rows[i - 1].t);
  }
  return d;
}

}  // namespace gearpulse::sim
