// Long-run bench: days of simulated driving through the whole daemon in this process (gearpulse::daemon::
// Daemon: its pipeline threads, retrainer, saves, journal and control socket), at `speedup` times real
// time, watching what must not grow.
//
// The drives are bmw-520i drives of mixed style from the simulator (seeds seed, seed+1, ...), each cut at
// a standstill near its end and followed by `park` s parked (engine off, GPS at 0 m/s). Each drive has the
// outage protocol's GPS outages (bench/outage_protocol.hpp: 60 s without a fix, the first 120 s in, then
// every 180 s), and at each drive's start the fake gpsd goes away for a second of wall time and comes back
// (a gpsd restart: the client reconnects). Time runs `speedup` times fast: the GPS epoch of drive second i
// goes out at i / speedup s of wall time, and the lighter ripple of drive time s plays at s / speedup s,
// written paced to a FIFO the ALSA file plugin captures from (8 kHz). Revs and speed therefore change
// `speedup` times faster than in a car; the tracker's 0.1 s window spans 0.1 x speedup s of driving.
// Everything the daemon's configuration counts in seconds is divided by `speedup`: retrain_interval
// (600 s), save_interval (300 s), store_hours; the young model's schedule is off (learn_young_time = 0:
// it counts moving time from the pairs' wall-clock stamps, which run `speedup` times slow), so the model
// is refitted by the interval rule alone (600 new pairs, or fewer: below). The store holds `store-hours` of
// driving (a quarter of the run's by default), so it is full from early on.
//
// Sampled every wall second: resident memory (VmRSS), open file descriptors and threads of this process;
// every simulated hour: the daemon's status over its control socket. Figures:
//   rss_growth_mb        peak RSS in the run's second half minus peak in its first half
//   store_growth_pct     most training pairs in the second half over most in the first half, in % above 1
//   store_peak_over_bound  most training pairs over store_hours x 3600 (a pair per second of driving)
//   fd_growth, thread_growth   the median count of fds (threads) over the last simulated hour minus
//                        that over the first (a fit's thread, a save's file, a GPS reconnect come and go)
//   fds_left, threads_left     after SIGTERM and the daemon's return, minus before it was made
//   pulse_error_pct      |pulses - expected| / expected, expected = the driven distance at wall pace x
//                        pulses_per_km (GPS through outages coasts or runs on the learned gears)
//   pulse_rate_excess    pulses minus max_frequency x wall time (the train's hard bound; <= 0)
//   outage_distance_pct  the share of the distance driven in GPS outages
//   pulse_error_of_outages  pulse_error_pct over outage_distance_pct: the share of the outages' distance
//                        the pulses miss or add (with a fix they follow GPS)
//   retrain_runs, gears, gps_reconnects
// Usage: bench_long_run [--drives N] [--drive-minutes M] [--park S] [--speedup K] [--seed S]
//                       [--store-hours H] [--require NAME<=VALUE ...]
// A week: --drives 14 (a 40-minute commute twice a day). The test command runs --drives 3 --speedup 30.
#include <dirent.h>
#include <fcntl.h>
#include <malloc.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "bench/outage_protocol.hpp"
#include "bench/requirements.hpp"
#include "daemon/config.hpp"
#include "daemon/daemon.hpp"
#include "daemon/fitter.hpp"
#include "drivers/clock.hpp"
#include "tests/test_util.hpp"
#include "tools/sim/lighter_signal.hpp"
#include "tools/sim/vehicle_sim.hpp"

namespace fs = std::filesystem;
namespace sim = gearpulse::sim;
using gearpulse::monotonic_ns;

namespace {

constexpr double kStep = 0.1;      // s of drive time between timeline points
constexpr unsigned kRate = 8000;   // Hz of the captured ripple
constexpr unsigned kPeriod = 256;  // frames per FIFO write and ALSA period
constexpr double kPulsesPerKm = 2485.0;
constexpr double kMaxFrequency = 1000.0;  // [output] max_frequency's default

struct Options {
  int drives = 14;
  double drive_minutes = 40.0;
  double park = 300.0;  // s parked after each drive
  double speedup = 20.0;
  std::uint64_t seed = 1;
  double store_hours = -1.0;  // < 0: a quarter of the run's driving
};

// What the car does at each kStep of simulated time.
struct Timeline {
  std::vector<float> speed;          // m/s
  std::vector<float> freq;           // Hz of the engine component, NaN = engine off
  std::vector<bool> fix;             // GPS has a fix
  std::vector<double> drive_starts;  // s of simulated time
  double distance = 0.0;             // m
  double outage_distance = 0.0;      // m driven without a GPS fix

  [[nodiscard]] double length() const { return static_cast<double>(speed.size()) * kStep; }
  [[nodiscard]] std::size_t at(double s) const {
    return std::min(speed.size() - 1, static_cast<std::size_t>(std::max(0.0, s / kStep)));
  }
};

Timeline make_timeline(const Options& o) {
  Timeline tl;
  const sim::Vehicle car = sim::bmw_520i();
  for (int d = 0; d < o.drives; ++d) {
    sim::DriveOptions opt;
    opt.style = sim::DrivingStyle::kMixed;
    opt.duration = o.drive_minutes * 60.0;
    opt.dt = kStep;
    opt.seed = o.seed + static_cast<std::uint64_t>(d);
    const sim::Drive drive = sim::simulate_drive(car, opt);
    // Cut at the last standstill of the drive's second half, so it ends parked; without one, the car
    // brakes to a stop at 2 m/s^2, declutched.
    std::size_t end = drive.truth.size();
    for (std::size_t i = drive.truth.size(); i-- > drive.truth.size() / 2;)
      if (drive.truth[i].speed < 0.05) {
        end = i + 1;
        break;
      }
    tl.drive_starts.push_back(tl.length());
    const auto push = [&tl](double speed, double freq, bool fix) {
      tl.speed.push_back(static_cast<float>(speed));
      tl.freq.push_back(static_cast<float>(freq));
      tl.fix.push_back(fix);
      tl.distance += speed * kStep;
      if (!fix) tl.outage_distance += speed * kStep;
    };
    for (std::size_t i = 0; i < end; ++i) {
      const sim::TruthSample& s = drive.truth[i];
      push(s.speed, s.freq, !gearpulse::bench::in_outage(s.t));
    }
    for (double v = drive.truth[end - 1].speed - 2.0 * kStep; v > 0.0; v -= 2.0 * kStep)
      push(v, car.idle_freq, true);
    for (double t = 0.0; t < o.park; t += kStep)
      push(0.0, std::nan(""), true);
  }
  return tl;
}

// The run's shared clock: simulated time s is at wall time t0 + s / speedup.
struct SimClock {
  std::atomic<std::int64_t> t0_ns{0};  // 0 until the ripple starts to flow
  double speedup = 1.0;
  [[nodiscard]] std::int64_t wall_ns(double s) const {
    return t0_ns.load() + static_cast<std::int64_t>(s / speedup * 1e9);
  }
  [[nodiscard]] double sim_now() const {
    const std::int64_t t0 = t0_ns.load();
    return t0 == 0 ? 0.0 : static_cast<double>(monotonic_ns() - t0) * 1e-9 * speedup;
  }
};

void sleep_until(std::int64_t ns) {
  const timespec ts = gearpulse::to_timespec(ns);
  ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

// Writes the ripple of the timeline to the FIFO, one period per period time, from the moment the capture
// opens it; then silence until the capture closes it (the daemon stopped).
void feed_audio(const fs::path& fifo, const Timeline& tl, SimClock& clock, const std::atomic<bool>& quit) {
  const int fd = ::open(fifo.c_str(), O_WRONLY);  // blocks until ALSA opens the infile
  if (fd < 0) return;
  sim::LighterSignalConfig g;
  g.sample_rate_hz = kRate;
  g.amplitude = 0.1;
  g.snr_db = 15.0;
  g.seed = 7;
  const double k = clock.speedup;
  sim::LighterSignal ripple(g, [&tl, k](double t) {
    const double s = t * k;
    return s >= tl.length() ? std::nan("") : static_cast<double>(tl.freq[tl.at(s)]);
  });
  std::vector<float> x(kPeriod);
  std::vector<std::int16_t> pcm(kPeriod);
  const std::int64_t period_ns = static_cast<std::int64_t>(kPeriod) * 1'000'000'000 / kRate;
  std::int64_t next = monotonic_ns();
  clock.t0_ns.store(next);
  while (!quit.load()) {
    ripple.generate(x);
    for (unsigned i = 0; i < kPeriod; ++i)
      pcm[i] = static_cast<std::int16_t>(std::lround(std::clamp(x[i], -1.0f, 1.0f) * 32767.0f));
    sleep_until(next);
    if (::write(fd, pcm.data(), sizeof(std::int16_t) * kPeriod) < 0) break;  // the capture closed it
    next += period_ns;
  }
  ::close(fd);
}

// A gpsd as libgps sees it: a banner on connection, then a TPV report per simulated second, with a fix
// (mode 3 and the speed) or without (mode 1) as the timeline says. At each drive's start it closes the
// connections and its socket for a second of wall time (a restart).
class FakeGpsd {
 public:
  explicit FakeGpsd(int port) : port_(port) { listen_now(); }
  ~FakeGpsd() {
    for (const int c : clients_)
      ::close(c);
    if (listen_ >= 0) ::close(listen_);
  }
  FakeGpsd(const FakeGpsd&) = delete;
  FakeGpsd& operator=(const FakeGpsd&) = delete;

  void run(const Timeline& tl, const SimClock& clock, const std::atomic<bool>& quit) {
    while (clock.t0_ns.load() == 0 && !quit.load())
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    std::size_t next_start = 1;  // the first drive starts with the daemon
    for (long i = 0; !quit.load() && i * 1.0 < tl.length(); ++i) {
      const double s = static_cast<double>(i);
      if (next_start < tl.drive_starts.size() && s >= tl.drive_starts[next_start]) {
        ++next_start;
        restart(clock.wall_ns(s) + 1'000'000'000);
      }
      serve_until(clock.wall_ns(s));
      const std::size_t at = tl.at(s);
      send_all(tpv(i, tl.fix[at], tl.speed[at]));
    }
    while (!quit.load())
      serve_until(monotonic_ns() + 100'000'000);
  }

 private:
  void listen_now() {
    listen_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    const int one = 1;
    ::setsockopt(listen_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port_));
    if (::bind(listen_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(listen_, 8) != 0) {
      std::fprintf(stderr, "fake gpsd: cannot listen on port %d: %s\n", port_, std::strerror(errno));
      std::exit(2);
    }
  }
  void restart(std::int64_t back_ns) {
    for (const int c : clients_)
      ::close(c);
    clients_.clear();
    ::close(listen_);
    listen_ = -1;
    sleep_until(back_ns);
    listen_now();
  }
  // Accepts connections and reads (and ignores) what clients send until `until_ns`.
  void serve_until(std::int64_t until_ns) {
    for (;;) {
      const std::int64_t left = until_ns - monotonic_ns();
      if (left <= 0) return;
      std::vector<pollfd> fds{{listen_, POLLIN, 0}};
      for (const int c : clients_)
        fds.push_back({c, POLLIN, 0});
      if (::poll(fds.data(), fds.size(), static_cast<int>(left / 1'000'000) + 1) <= 0) continue;
      if (fds[0].revents & POLLIN) {
        const int c = ::accept4(listen_, nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK);
        if (c >= 0) {
          clients_.push_back(c);
          send_one(c, R"({"class":"VERSION","release":"3.22","rev":"3.22","proto_major":3,"proto_minor":14})"
                      "\n");
        }
      }
      for (std::size_t i = 1; i < fds.size(); ++i) {
        if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
        char buf[512];
        if (::recv(fds[i].fd, buf, sizeof buf, 0) <= 0) drop(fds[i].fd);
      }
    }
  }
  void drop(int c) {
    ::close(c);
    clients_.erase(std::remove(clients_.begin(), clients_.end(), c), clients_.end());
  }
  static bool send_one(int c, const std::string& line) {
    return ::send(c, line.data(), line.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(line.size());
  }
  void send_all(const std::string& line) {
    std::vector<int> gone;
    for (const int c : clients_)
      if (!send_one(c, line)) gone.push_back(c);
    for (const int c : gone)
      drop(c);
  }
  static std::string tpv(long second, bool fix, double speed) {
    const time_t t = 1'767'225'600 + second;  // 2026-01-01T00:00:00Z + simulated seconds
    tm utc{};
    ::gmtime_r(&t, &utc);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%S.000Z", &utc);
    if (!fix)
      return fmt::format(R"({{"class":"TPV","device":"/dev/sim","mode":1,"time":"{}"}})", stamp) + "\n";
    return fmt::format(R"({{"class":"TPV","device":"/dev/sim","mode":3,"time":"{}","ept":0.005,"lat":52.5,)"
                       R"("lon":13.4,"alt":40.0,"speed":{:.3f},"eps":0.2}})",
                       stamp, speed) +
           "\n";
  }

  int port_;
  int listen_ = -1;
  std::vector<int> clients_;
};

long count_entries(const char* dir) {
  long n = 0;
  if (DIR* d = ::opendir(dir)) {
    while (const dirent* e = ::readdir(d))
      n += e->d_name[0] != '.';
    ::closedir(d);
  }
  return n;
}
// Open descriptors, less the one counting them holds.
long open_fds() {
  return count_entries("/proc/self/fd") - 1;
}
long threads() {
  return count_entries("/proc/self/task");
}
double rss_mb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::strtod(line.c_str() + 6, nullptr) / 1024.0;
  return 0.0;
}

struct Hour {
  double rss_peak = 0.0;
  std::vector<long> fds, threads;  // one count a wall second
  double pairs_peak = 0.0;         // the most training pairs status gave
  nlohmann::json status;           // at the hour's end
};

// The count most seconds of an hour saw: a fit's thread, a save's file or a GPS reconnect come and go.
long median(std::vector<long> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

nlohmann::json ask_status(const std::string& socket) {
  gearpulse::test::LineClient c(socket);
  if (!c.connected() || !c.send_all("{\"cmd\":\"status\"}\n")) return {};
  const auto line = c.read_line(10'000);
  if (!line) return {};
  return nlohmann::json::parse(*line, nullptr, false);
}

bool parse_args(int argc, char** argv, Options& o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return false;
    const char* v = argv[++i];
    if (a == "--drives")
      o.drives = std::atoi(v);
    else if (a == "--drive-minutes")
      o.drive_minutes = std::atof(v);
    else if (a == "--park")
      o.park = std::atof(v);
    else if (a == "--speedup")
      o.speedup = std::atof(v);
    else if (a == "--seed")
      o.seed = std::strtoull(v, nullptr, 10);
    else if (a == "--store-hours")
      o.store_hours = std::atof(v);
    else
      return false;
  }
  return o.drives >= 1 && o.drive_minutes >= 5.0 && o.park >= 0.0 && o.speedup >= 1.0 && o.speedup <= 100.0;
}

}  // namespace

int main(int argc, char** argv) {
  gearpulse::bench::Requirements req;
  Options o;
  if (!req.parse(argc, argv) || !parse_args(argc, argv, o)) {
    std::fprintf(stderr,
                 "usage: bench_long_run [--drives N] [--drive-minutes M] [--park S] [--speedup K (1-100)] "
                 "[--seed S] [--store-hours H] [--require NAME<=VALUE ...]\n");
    return 2;
  }
  (void)::mallopt(M_ARENA_MAX, 2);  // as gearpulsed's main()
  // Blocked before any thread starts, so every thread inherits it and the daemon's signalfd takes them.
  sigset_t mask;
  sigemptyset(&mask);
  for (int sig : {SIGTERM, SIGINT, SIGHUP})
    sigaddset(&mask, sig);
  pthread_sigmask(SIG_BLOCK, &mask, nullptr);
  ::signal(SIGPIPE, SIG_IGN);

  const Timeline tl = make_timeline(o);
  const double driving_h = (tl.length() - o.drives * o.park) / 3600.0;
  if (o.store_hours < 0.0) o.store_hours = driving_h / 4.0;
  const double k = o.speedup;
  std::printf(
      "long run: %d drives, %.2f h of driving (%.1f km), %.2f h in all, at %.0fx: %.1f min of wall "
      "time; store of %.2f h of driving\n",
      o.drives, driving_h, tl.distance / 1000.0, tl.length() / 3600.0, k, tl.length() / k / 60.0,
      o.store_hours);
  std::fflush(stdout);

  gearpulse::test::TempDir dir;
  const fs::path fifo = dir / "ripple.fifo";
  if (::mkfifo(fifo.c_str(), 0600) != 0) return 2;
  gearpulse::test::write_text(dir / "asound.conf",
                              "pcm.longrun { type file slave.pcm null file \"/dev/null\" "
                              "infile \"" +
                                  fifo.string() + "\" format raw }\n");
  ::setenv("ALSA_CONFIG_PATH", ("/usr/share/alsa/alsa.conf:" + (dir / "asound.conf").string()).c_str(), 1);
  const int port = gearpulse::test::free_port();
  const std::string socket = (dir / "control.sock").string();
  // At k times real time the pairs come k a second: the store's hours hold k times the pairs the
  // configuration counts (one a second), and the retrain threshold is kept within that count.
  const auto min_new_samples = std::min<long>(600, std::lround(std::floor(o.store_hours / k * 3600.0)));
  const std::string config_text = fmt::format(
      "[audio]\ndevice = \"longrun\"\nrate = {}\nformat = \"S16_LE\"\nperiod_frames = {}\n"
      "[gps]\nhost = \"127.0.0.1\"\nport = {}\n"
      "[output]\nkind = \"none\"\npulses_per_km = {}\nmax_frequency = {}\n"
      "[model]\nstate_dir = \"{}\"\nretrain_interval = {}\nsave_interval = {}\nstore_hours = {}\n"
      "min_new_samples = {}\nlearn_young_time = 0\n"
      "[control]\nsocket = \"{}\"\n[log]\nlevel = \"warn\"\n",
      kRate, kPeriod, port, kPulsesPerKm, kMaxFrequency, (dir / "state").string(), 600.0 / k, 300.0 / k,
      o.store_hours / k, min_new_samples, socket);
  gearpulse::test::write_text(dir / "gearpulse.toml", config_text);
  gearpulse::daemon::Config config;
  try {
    config = gearpulse::daemon::load_config((dir / "gearpulse.toml").string());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 2;
  }
  gearpulse::daemon::apply_log_level(config.log.level);

  const long fds_before = open_fds();
  const long threads_before = threads();
  SimClock clock;
  clock.speedup = k;
  std::atomic<bool> quit{false};
  std::atomic<bool> daemon_done{false};
  std::vector<Hour> hours(static_cast<std::size_t>(std::ceil(tl.length() / 3600.0)));
  std::mutex hours_mutex;
  const auto wall_start = std::chrono::steady_clock::now();

  std::thread feeder([&] { feed_audio(fifo, tl, clock, quit); });
  auto gpsd = std::make_unique<FakeGpsd>(port);
  std::thread gps([&] { gpsd->run(tl, clock, quit); });
  std::thread monitor([&] {
    // From the daemon's first answer on: its threads and files are all there.
    while (!daemon_done.load() && !ask_status(socket).is_object())
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    std::size_t reported = 0;
    while (!daemon_done.load()) {
      std::this_thread::sleep_for(std::chrono::seconds(1));
      const double s = clock.sim_now();
      const std::size_t h = std::min(hours.size() - 1, static_cast<std::size_t>(s / 3600.0));
      // Counted before the status is asked for: the daemon's side of that connection is closed a moment
      // after this side's.
      const double rss = rss_mb();
      const long fds = open_fds(), tasks = threads();
      const nlohmann::json now = ask_status(socket);
      {
        std::lock_guard lock(hours_mutex);
        Hour& hr = hours[h];
        hr.rss_peak = std::max(hr.rss_peak, rss);
        hr.fds.push_back(fds);
        hr.threads.push_back(tasks);
        hr.pairs_peak = std::max(hr.pairs_peak, now.is_object() ? now.value("training_samples", 0.0) : 0.0);
      }
      const bool over = s >= tl.length();
      if (h > reported || over) {
        // The hour just ended (or the run): the daemon's status.
        const std::size_t ended = over ? hours.size() - 1 : h - 1;
        nlohmann::json st = ask_status(socket);
        std::lock_guard lock(hours_mutex);
        hours[ended].status = st;
        const Hour& hr = hours[ended];
        std::printf(
            "hour %2zu: rss %.1f MB, fds %ld, threads %ld, pairs %.0f, pulses %s, gears %s, retrains %s\n",
            ended + 1, hr.rss_peak, median(hr.fds), median(hr.threads), hr.pairs_peak,
            st.value("pulses", nlohmann::json()).dump().c_str(),
            st.contains("model") ? st["model"].value("gears", nlohmann::json()).dump().c_str() : "?",
            st.contains("model") ? st["model"].value("retrain_runs", nlohmann::json()).dump().c_str() : "?");
        std::fflush(stdout);
        reported = h;
        if (over) {
          ::kill(::getpid(), SIGTERM);
          break;
        }
      }
    }
  });

  int rc = 0;
  {
    gearpulse::daemon::Daemon daemon(config, (dir / "gearpulse.toml").string(),
                                     gearpulse::daemon::make_estimator_fitter());
    rc = daemon.run();
  }
  daemon_done.store(true);
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  quit.store(true);
  monitor.join();
  feeder.join();
  gps.join();
  gpsd.reset();
  const long fds_left = open_fds() - fds_before;
  const long threads_left = threads() - threads_before;
  std::printf("daemon returned %d after %.0f s of wall time\n", rc, wall_s);

  // Halves of the run by simulated hours (a last partial hour counts with the second half).
  const std::size_t n = hours.size();
  double rss_first = 0.0, rss_second = 0.0, store_first = 0.0, store_second = 0.0;
  for (std::size_t h = 0; h < n; ++h) {
    const bool second = 2 * h >= n;
    (second ? rss_second : rss_first) = std::max(second ? rss_second : rss_first, hours[h].rss_peak);
    const double pairs = hours[h].pairs_peak;
    (second ? store_second : store_first) = std::max(second ? store_second : store_first, pairs);
  }
  const nlohmann::json& last = hours.back().status;
  const double pulses = last.value("pulses", 0.0);
  // The pulse train runs at the car's speed in wall time: the distance of the drives over speedup.
  const double expected = tl.distance / k / 1000.0 * kPulsesPerKm;

  std::printf("figure sim_hours = %.6g\nfigure driving_hours = %.6g\nfigure wall_s = %.6g\n",
              tl.length() / 3600.0, driving_h, wall_s);
  req.report("daemon_rc", rc);
  req.report("rss_first_half_mb", rss_first);
  req.report("rss_second_half_mb", rss_second);
  req.report("rss_growth_mb", rss_second - rss_first);
  req.report("store_first_half_pairs", store_first);
  req.report("store_second_half_pairs", store_second);
  req.report("store_growth_pct", store_first > 0.0 ? (store_second / store_first - 1.0) * 100.0 : 100.0);
  // A pair comes of a GPS fix, one a second of driving at most: store_hours of driving hold no more.
  const double store_bound = o.store_hours * 3600.0;
  req.report("store_bound_pairs", store_bound);
  req.report("store_peak_over_bound", std::max(store_first, store_second) / store_bound);
  req.report("fd_growth", static_cast<double>(median(hours[n - 1].fds) - median(hours[0].fds)));
  req.report("thread_growth", static_cast<double>(median(hours[n - 1].threads) - median(hours[0].threads)));
  req.report("fds_left", static_cast<double>(fds_left));
  req.report("threads_left", static_cast<double>(threads_left));
  req.report("pulses", pulses);
  req.report("pulses_expected", expected);
  const double pulse_error = expected > 0.0 ? std::abs(pulses - expected) / expected : 1.0;
  req.report("pulse_error_pct", pulse_error * 100.0);
  // With a fix the pulses follow GPS; what they miss is of the outages' distance (and a first outage
  // before any model coasts down). The share of that distance they miss:
  req.report("outage_distance_pct", tl.outage_distance / tl.distance * 100.0);
  req.report("pulse_error_of_outages", pulse_error * tl.distance / tl.outage_distance);
  req.report("pulse_rate_excess", pulses - kMaxFrequency * wall_s);
  req.report("retrain_runs", last.contains("model") ? last["model"].value("retrain_runs", 0.0) : 0.0);
  req.report("gears", last.contains("model") ? last["model"].value("gears", 0.0) : 0.0);
  req.report("gps_reconnects", last.contains("gps") ? last["gps"].value("reconnects", 0.0) : 0.0);
  return req.exit_status();
}
