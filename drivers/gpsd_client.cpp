#include "drivers/gpsd_client.hpp"

#include <gps.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <string_view>

#include "drivers/clock.hpp"

namespace gearpulse {
namespace {

constexpr int kPollUs = 100'000;  // how long one wait for data may delay stop()

// Whether a fix of gpsd's status (gps_fix_t.status) carries a speed measured over ground. Dead reckoning
// alone (a receiver extrapolating its last velocity through a tunnel; NMEA's 'E' mode indicator, GGA
// quality 6), a time-only or a simulated fix does not: it must neither drive the pulses, which have the
// engine for that, nor teach the estimator. GNSS with dead reckoning (STATUS_GNSSDR) is measured.
bool measured_speed(int status) noexcept {
  return status != STATUS_DR && status != STATUS_TIME && status != STATUS_SIM;
}

// libgps closes and frees what gps_open set up; this keeps that pairing exception-safe.
class GpsConnection {
 public:
  GpsConnection(const std::string& host, const std::string& port) {
    errno = 0;
    if (::gps_open(host.c_str(), port.c_str(), &data_) != 0) {
      const int err = errno;
      error_ = "cannot connect to gpsd at " + host + ":" + port + ": " + ::gps_errstr(err);
      return;
    }
    open_ = true;
    if (::gps_stream(&data_, WATCH_ENABLE | WATCH_JSON, nullptr) != 0) {
      try {
        error_ = "gpsd at " + host + ":" + port + " refused the watch request";
      } catch (...) {
        ::gps_close(&data_);  // a constructor that throws gets no destructor
        throw;
      }
    }
  }
  ~GpsConnection() {
    if (open_) ::gps_close(&data_);
  }
  GpsConnection(const GpsConnection&) = delete;
  GpsConnection& operator=(const GpsConnection&) = delete;

  [[nodiscard]] bool ok() const noexcept { return open_ && error_.empty(); }
  [[nodiscard]] const std::string& error() const noexcept { return error_; }
  gps_data_t& data() noexcept { return data_; }

 private:
  gps_data_t data_{};
  bool open_ = false;
  std::string error_;
};

double fix_seconds(const timespec_t& ts) noexcept {
  if (ts.tv_sec == 0 && ts.tv_nsec == 0) return std::nan("");
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

}  // namespace

const char* to_string(GpsdState state) noexcept {
  switch (state) {
    case GpsdState::kStopped:
      return "stopped";
    case GpsdState::kConnecting:
      return "connecting";
    case GpsdState::kConnected:
      return "connected";
  }
  return "unknown";
}

GpsdClient::GpsdClient(GpsdConfig config, Callback on_report)
    : config_(std::move(config)), on_report_(std::move(on_report)) {}

GpsdClient::~GpsdClient() {
  stop();
}

void GpsdClient::start() {
  std::lock_guard lock(mutex_);
  if (thread_.joinable()) return;
  stop_requested_ = false;
  status_.state = GpsdState::kConnecting;
  beat();
  thread_ = std::thread([this] { run(); });
}

void GpsdClient::stop() {
  {
    std::lock_guard lock(mutex_);
    stop_requested_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard lock(mutex_);
  status_.state = GpsdState::kStopped;
}

GpsdStatus GpsdClient::status() const {
  std::lock_guard lock(mutex_);
  return status_;
}

std::int64_t GpsdClient::heartbeat_ns() const noexcept {
  if (connecting_.load(std::memory_order_relaxed)) return monotonic_ns();
  return beat_ns_.load(std::memory_order_relaxed);
}

void GpsdClient::beat() noexcept {
  beat_ns_.store(monotonic_ns(), std::memory_order_relaxed);
}

bool GpsdClient::wait_backoff(std::chrono::milliseconds delay) {
  const auto end = std::chrono::steady_clock::now() + delay;
  std::unique_lock lock(mutex_);
  for (;;) {
    beat();
    const auto slice = std::min(end, std::chrono::steady_clock::now() + std::chrono::nanoseconds(kBeatNs));
    if (wake_.wait_until(lock, slice, [this] { return stop_requested_; })) return false;
    if (slice >= end) return true;
  }
}

void GpsdClient::set_error(std::string message, bool connection_lost) {
  std::lock_guard lock(mutex_);
  status_.last_error = std::move(message);
  ++status_.failures;
  if (connection_lost) status_.state = GpsdState::kConnecting;
}

void GpsdClient::run() {
  std::chrono::milliseconds backoff = config_.backoff_min;
  const std::string server = config_.host + ":" + config_.port;  // for the errors of a lost connection
  auto stopping = [this] {
    std::lock_guard lock(mutex_);
    return stop_requested_;
  };
  while (!stopping()) {
    connecting_.store(true, std::memory_order_relaxed);
    GpsConnection conn(config_.host, config_.port);
    beat();
    connecting_.store(false, std::memory_order_relaxed);
    if (!conn.ok()) {
      set_error(conn.error(), true);
      if (!wait_backoff(backoff)) break;
      backoff = std::min(backoff * 2, config_.backoff_max);
      continue;
    }
    {
      std::lock_guard lock(mutex_);
      status_.state = GpsdState::kConnected;
      ++status_.connects;
    }
    device_.clear();  // a gpsd started again may name its devices anew
    char message[4096];
    while (!stopping()) {
      beat();
      errno = 0;
      if (!::gps_waiting(&conn.data(), kPollUs)) {
        if (const int err = errno; err != 0 && err != EINTR && err != EAGAIN) {
          set_error("waiting for gpsd at " + server + ": " + std::strerror(err), true);
          break;
        }
        continue;
      }
      // Drain everything that is already buffered; only the newest position/velocity report counts.
      std::optional<GpsReport> newest;
      bool newest_unmeasured = false;  // its speed was refused as not measured (measured_speed)
      std::uint64_t drained = 0;
      std::uint64_t bad = 0;
      std::uint64_t other = 0;
      bool lost = false;
      do {
        beat();  // a flood of reports keeps the thread here: it is busy, not hung
        message[0] = '\0';
        errno = 0;
        const int n = ::gps_read(&conn.data(), message, sizeof message);
        if (n < 0) {
          lost = true;
          break;
        }
        if (n == 0) break;
        if (std::strstr(message, "\"class\":\"TPV\"") == nullptr) {
          if (message[0] != '{') ++bad;  // not JSON at all: counted, skipped
          continue;
        }
        const gps_fix_t& fix = conn.data().fix;
        GpsReport r;
        r.rx_ns = monotonic_ns();
        r.mode = (fix.mode >= 0 && fix.mode <= 3) ? fix.mode : 0;
        r.speed = std::isfinite(fix.speed) && fix.speed >= 0.0 ? fix.speed : std::nan("");
        r.eps = std::isfinite(fix.eps) && fix.eps >= 0.0 ? fix.eps : std::nan("");
        r.fix_time = fix_seconds(fix.time);
        const bool unmeasured = r.usable() && !measured_speed(fix.status);
        if (unmeasured) r.speed = std::nan("");
        // gpsd serves every device it has (a modem's NMEA port beside the receiver, one with no fix): the
        // device of the last usable fix is followed, and another's reports count only once that one has
        // given no usable fix for the no-fix timeout. Mixed, a device without a fix made GPS flap between
        // fix and none, and two with fixes made a training pair at every crossing of their times.
        const std::string_view device = conn.data().dev.path;
        if (!device_.empty() && device != device_ && r.rx_ns - device_fix_ns_ <= timeout_ns()) {
          ++other;
          continue;
        }
        if (r.usable()) {
          if (device != device_) {
            device_ = device;
            gate_.reset();  // the last speed it judges by was another receiver's
          }
          device_fix_ns_ = r.rx_ns;
        }
        newest_unmeasured = unmeasured;
        if (newest) ++drained;
        newest = r;
      } while (::gps_waiting(&conn.data(), 0));
      if (newest) {
        // A speed no car reaches (or reaches that fast) is published as none: a glitch of the receiver
        // must neither drive the pulses nor teach the estimator.
        double refused = std::nan("");
        if (newest->usable() && gate_.check(newest->fix_time, static_cast<double>(newest->rx_ns) * 1e-9,
                                            newest->speed) != GpsSpeedGate::Verdict::kAccepted) {
          refused = newest->speed;
          newest->speed = std::nan("");
        }
        // What the batch held (reads that did not parse, reports the newest replaced, a refused speed) is
        // counted before the report is published, the report itself once it is: whoever sees the report
        // finds its batch counted, and whoever sees it counted finds it published.
        {
          std::lock_guard lock(mutex_);
          status_.superseded += drained;
          status_.bad_reads += bad;
          status_.other_device += other;
          if (refused == refused) {
            ++status_.implausible;
            status_.last_implausible = refused;
          }
          if (newest_unmeasured) ++status_.unmeasured;
        }
        history_.record(*newest);
        {
          std::lock_guard lock(mutex_);
          ++status_.reports;
        }
        backoff = config_.backoff_min;
        if (on_report_) on_report_(*newest);
      } else if (bad || other) {
        std::lock_guard lock(mutex_);
        status_.bad_reads += bad;
        status_.other_device += other;
      }
      if (lost) {
        const int err = errno;
        set_error(err ? "reading from gpsd at " + server + ": " + std::strerror(err)
                      : "gpsd at " + server + " closed the connection",
                  true);
        break;
      }
    }
    if (stopping()) break;
    // Lost the connection: back off before reconnecting so a crashing gpsd is not hammered. Only a
    // position report resets the delay (above): a gpsd that greets and hangs up, or sends nothing but
    // its banner, is not a working one.
    if (!wait_backoff(backoff)) break;
    backoff = std::min(backoff * 2, config_.backoff_max);
  }
}

}  // namespace gearpulse
