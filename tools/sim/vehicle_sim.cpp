// The driver and drivetrain model. Dynamics run at a fixed 50 ms step whatever the output grid, so a
// seed gives one drive; outputs are interpolated onto k * dt.
#include "tools/sim/vehicle_sim.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

namespace gearpulse::sim {
namespace {

constexpr double kStep = 0.05;  // s, dynamics step

// Where the driver wants to go next: a target speed held for a while, or a stop.
struct Leg {
  double target = 0.0;  // m/s
  double duration = 0.0;
  bool stop_after = false;
  double stand = 0.0;  // s at standstill after the stop
};

enum class Terrain { kUrban, kCountry, kHighway, kJam };

class RouteGenerator {
 public:
  explicit RouteGenerator(DrivingStyle style, std::mt19937_64& rng, double duration)
      : style_(style), rng_(rng), duration_(duration) {}

  Leg next(double t) {
    const Terrain terrain = terrain_at(t);
    Leg leg;
    switch (terrain) {
      case Terrain::kUrban:
        leg.target = uniform(7.0, 16.0);
        leg.duration = uniform(12.0, 70.0);
        leg.stop_after = uniform(0, 1) < 0.4;
        leg.stand = uniform(4.0, 50.0);
        break;
      case Terrain::kCountry:
        leg.target = uniform(16.0, 26.0);
        leg.duration = uniform(30.0, 150.0);
        leg.stop_after = uniform(0, 1) < 0.06;
        leg.stand = uniform(5.0, 30.0);
        break;
      case Terrain::kHighway: {
        const double u = uniform(0, 1);  // congestion, slower stretches, free flow
        leg.target = u < 0.1 ? uniform(8.0, 15.0) : (u < 0.25 ? uniform(15.0, 22.0) : uniform(25.0, 36.0));
      }
        leg.duration = uniform(50.0, 300.0);
        leg.stop_after = uniform(0, 1) < 0.04;  // toll booth, congestion
        leg.stand = uniform(5.0, 20.0);
        break;
      case Terrain::kJam:
        // Crawling below first gear's idle speed (clutch slip) alternates with short rolls.
        leg.target = uniform(0, 1) < 0.45 ? uniform(0.6, 2.0) : uniform(2.0, 7.0);
        leg.duration = uniform(4.0, 30.0);
        leg.stop_after = uniform(0, 1) < 0.5;
        leg.stand = uniform(2.0, 40.0);
        break;
    }
    return leg;
  }

 private:
  Terrain terrain_at(double t) {
    switch (style_) {
      case DrivingStyle::kUrban:
        return Terrain::kUrban;
      case DrivingStyle::kHighway:
        // A highway trip still starts and ends in town (six minutes each way).
        return (t < 360.0 || t > duration_ - 360.0) ? Terrain::kUrban : Terrain::kHighway;
      case DrivingStyle::kTrafficJam: {
        // A commute: mostly stop-and-go, broken by releases into town traffic and a free-flowing stretch.
        const double u = uniform(0, 1);
        return u < 0.1 ? Terrain::kCountry : (u < 0.25 ? Terrain::kUrban : Terrain::kJam);
      }
      case DrivingStyle::kMixed:
        break;
    }
    // Mixed: blocks of a few minutes of city, residential, country and highway in turn (as in section 4).
    if (t >= block_end_) {
      block_end_ = t + uniform(240.0, 480.0);
      block_index_ = (block_index_ + 1) % 4;
      static constexpr Terrain kCycle[4] = {Terrain::kUrban, Terrain::kCountry, Terrain::kUrban,
                                            Terrain::kHighway};
      block_ = kCycle[block_index_];
    }
    return block_;
  }

  double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }

  DrivingStyle style_;
  std::mt19937_64& rng_;
  double duration_;
  double block_end_ = -1.0;
  int block_index_ = -1;
  Terrain block_ = Terrain::kUrban;
};

enum class Phase { kStand, kLaunch, kDrive, kShift, kCoastToStop };

struct State {
  double t = 0.0;
  double v = 0.0;
  double f = 0.0;
  int gear = 0;
  Clutch clutch = Clutch::kDisengaged;
};

class DriveSimulator {
 public:
  DriveSimulator(const Vehicle& vehicle, const DriveOptions& options)
      : veh_(vehicle),
        rng_(options.seed),
        route_(options.style, rng_, options.duration),
        cold_start_(options.cold_start),
        warm_up_(options.warm_up),
        skip_downshift_(options.skip_downshift) {
    aggressiveness_ = uniform(0.4, 0.8);  // ordinary drivers, not launches at full throttle
    state_.f = warm_idle_at(0.0);
    stand_left_ = uniform(3.0, 10.0);
    leg_ = route_.next(0.0);
  }

  const State& state() const { return state_; }

  void step() {
    const double h = kStep;
    update_route(h);
    idle_wobble_ += (-idle_wobble_ / 2.0) * h + 0.004 * std::sqrt(h) * normal();
    const double idle = warm_idle_at(state_.t) * (1.0 + idle_wobble_);
    jitter_ += (-jitter_ / 8.0) * h + 0.02 * std::sqrt(h) * normal();
    const double target = stopping_ ? 0.0 : leg_.target * (1.0 + jitter_);
    if (veh_.is_cvt()) {
      step_cvt(h, target, idle);
    } else {
      step_manual(h, target, idle);
    }
    state_.t += h;
  }

 private:
  double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }
  double normal() { return std::normal_distribution<double>(0.0, 1.0)(rng_); }

  void update_route(double h) {
    if (phase_ == Phase::kStand) {
      stand_left_ -= h;
      if (stand_left_ <= 0.0 && stopping_) {
        stopping_ = false;
        leg_ = route_.next(state_.t);
      }
      return;
    }
    if (stopping_) return;
    leg_.duration -= h;
    if (leg_.duration > 0.0) return;
    if (leg_.stop_after) {
      stopping_ = true;
      stand_left_ = leg_.stand;
      brake_ = uniform(0.9, 2.4);
      coast_speed_ = uniform(1.5, 6.0);
    } else {
      leg_ = route_.next(state_.t);
    }
  }

  // Acceleration the driver asks for, limited by the engine in the current gear.
  double desired_accel(double target, double gear_theta) {
    double a = 0.45 * (target - state_.v);
    const double theta1 = veh_.is_cvt() ? veh_.cvt_theta_min : veh_.theta.front();
    const double cap = aggressiveness_ * veh_.max_accel * std::pow(theta1 / gear_theta, 0.8);
    return std::clamp(a, -3.0, std::max(cap, 0.05));
  }

  void step_manual(double h, double target, double idle) {
    State& s = state_;
    switch (phase_) {
      case Phase::kStand:
        s.v = 0.0;
        s.gear = 0;
        s.clutch = Clutch::kDisengaged;
        s.f = idle;
        if (!stopping_ && stand_left_ <= 0.0) start_launch();
        break;
      case Phase::kLaunch: {
        // First gear, clutch slipping: the engine is held at the launch speed while the car catches up.
        s.gear = 1;
        s.clutch = Clutch::kSlipping;
        const double theta = veh_.theta[0];
        // Crawling below first gear's idle speed: the engine sits just above idle on a slipping clutch.
        // Aiming just above it, the clutch comes in as soon as the car nears the target speed.
        const double f_hold = target < idle * theta
                                  ? idle * crawl_factor_
                                  : std::max(idle, std::min(launch_freq_, 0.95 * target / theta));
        s.f += (std::max(f_hold, idle) - s.f) * std::min(1.0, h / 0.3);
        double a = std::min(desired_accel(target, theta), 0.8 * aggressiveness_ * veh_.max_accel);
        const bool crawling = target < idle * theta;
        if (!crawling) {
          // A driver lets the clutch in within a second or two: the car reaches the engine's speed by then.
          slip_left_ -= h;
          a = std::max(a, (theta * f_hold - s.v) / std::max(slip_left_, h));
        } else {
          slip_left_ = uniform(0.8, 2.5);
        }
        if (stopping_) a = -brake_;
        s.v = std::max(0.0, s.v + a * h);
        if (stopping_ && s.v < coast_speed_) {
          phase_ = Phase::kCoastToStop;
        } else if (s.v / theta >= s.f) {
          phase_ = Phase::kDrive;
          s.clutch = Clutch::kEngaged;
          s.f = s.v / theta;
        }
        break;
      }
      case Phase::kDrive: {
        const int g = s.gear;
        const double theta = veh_.theta[g - 1];
        double a = stopping_ ? -brake_ : desired_accel(target, theta);
        if (s.v / theta >= veh_.max_freq * 0.98 && a > 0) a = 0.0;
        s.v = std::max(0.0, s.v + a * h);
        s.f = s.v / theta;
        s.clutch = Clutch::kEngaged;
        if (stopping_ && (s.v < coast_speed_ || s.f < idle * 1.1)) {
          phase_ = Phase::kCoastToStop;
          break;
        }
        if (s.f < idle * 1.05) {
          if (g == 1) {
            phase_ = Phase::kLaunch;  // riding the clutch in first
            slip_left_ = uniform(0.8, 2.5);
          } else {
            start_shift(lowest_comfortable_gear(idle));
          }
          break;
        }
        const int max_gear = veh_.gears();
        if (g < max_gear && !stopping_) {
          const double next_f = s.v / veh_.theta[g];
          const bool accelerating = a > 0.4;
          const bool over_point = s.f > upshift_point_ * (accelerating ? 1.0 : 0.8);
          const bool cruising = std::abs(a) < 0.25 && next_f > veh_.downshift_freq * cruise_margin_;
          // Never into a gear the driver would at once shift down from: without this the driver hunted
          // between two gears at low speed (up on the rev point, down below the downshift point a second
          // later), a habit no driver has. The margin covers the speed lost while the clutch is out.
          const bool lugging = next_f < 1.1 * veh_.downshift_freq;
          if ((over_point || cruising) && next_f > idle * 1.2 && !lugging) {
            start_shift(g + 1);
            break;
          }
        }
        if (g > 1 && s.f < veh_.downshift_freq * (stopping_ ? 0.75 : 0.95) && !(stopping_ && g <= 2)) {
          // Braking, some drivers skip a gear (4 -> 2, 5 -> 3) where the revs allow it.
          const bool braking = stopping_ || a < -1.0;
          const bool skip = braking && skip_downshift_ > 0.0 && g > 2 &&
                            s.v / veh_.theta[g - 3] < 0.8 * veh_.max_freq &&
                            uniform(0.0, 1.0) < skip_downshift_;
          start_shift(skip ? g - 2 : g - 1);
        }
        break;
      }
      case Phase::kShift: {
        s.gear = 0;
        s.clutch = Clutch::kDisengaged;
        const double a = stopping_ ? -0.8 * brake_ : -0.3;
        s.v = std::max(0.0, s.v + a * h);
        const double f_next = s.v / veh_.theta[shift_to_ - 1];
        const double f_goal = shift_to_idle_ ? idle : std::max(idle, f_next);
        s.f += (f_goal - s.f) * std::min(1.0, h / shift_tau_);
        shift_left_ -= h;
        if (shift_left_ <= 0.0) {
          if (f_next < idle * 1.02) {
            phase_ = shift_to_ == 1 ? Phase::kLaunch : Phase::kCoastToStop;
            if (phase_ == Phase::kLaunch) {
              launch_freq_ = idle * uniform(1.2, 1.6);
              slip_left_ = uniform(0.8, 2.5);
            }
          } else {
            phase_ = Phase::kDrive;
            s.gear = shift_to_;
            s.clutch = Clutch::kEngaged;
            s.f = f_next;
          }
        }
        break;
      }
      case Phase::kCoastToStop: {
        s.gear = 0;
        s.clutch = Clutch::kDisengaged;
        s.f += (idle - s.f) * std::min(1.0, h / 0.5);
        if (stopping_) {
          s.v = std::max(0.0, s.v - brake_ * h);
          if (s.v <= 0.0) {
            s.v = 0.0;
            phase_ = Phase::kStand;
          }
        } else {
          // The jam moved again before we stopped: pick a gear for the speed we still have.
          s.v = std::max(0.0, s.v - 0.3 * h);
          if (s.v / veh_.theta[0] < idle * 1.3) {
            start_launch();
          } else {
            start_shift(lowest_comfortable_gear(idle));
          }
        }
        break;
      }
    }
  }

  // Continuously variable transmission: the ratio follows the throttle, so v/f never settles on a ladder;
  // at speed the ratio saturates at its top value (one tight cluster).
  void step_cvt(double h, double target, double idle) {
    State& s = state_;
    if (phase_ == Phase::kStand) {
      s.v = 0.0;
      s.f = idle;
      s.gear = 0;
      s.clutch = Clutch::kDisengaged;
      if (!stopping_ && stand_left_ <= 0.0) phase_ = Phase::kDrive;
      return;
    }
    const double a = stopping_ ? -brake_ : desired_accel(target, veh_.cvt_theta_min * 1.5);
    s.v = std::max(0.0, s.v + a * h);
    const double load = std::clamp(a / veh_.max_accel, 0.0, 1.0);
    const double f_want = idle * 1.4 + load * (veh_.max_freq * 0.45) + 4.0 * jitter_ / 0.02;
    cvt_f_ += (f_want - cvt_f_) * std::min(1.0, h / 1.5);
    const double theta = std::clamp(s.v / std::max(cvt_f_, idle), veh_.cvt_theta_min, veh_.cvt_theta_max);
    s.f = std::max(idle, s.v / theta);  // torque converter below the lowest ratio
    s.gear = 1;
    s.clutch = Clutch::kEngaged;
    if (stopping_ && s.v <= 0.0) {
      phase_ = Phase::kStand;
      s.gear = 0;
      s.clutch = Clutch::kDisengaged;
    }
  }

  // The idle a cold engine settles towards at time t: (1 + cold_start) x idle_freq at the start, falling
  // back to idle_freq with time constant warm_up.
  [[nodiscard]] double warm_idle_at(double t) const {
    return veh_.idle_freq * (1.0 + (cold_start_ > 0.0 ? cold_start_ * std::exp(-t / warm_up_) : 0.0));
  }

  void start_launch() {
    phase_ = Phase::kLaunch;
    launch_freq_ = warm_idle_at(state_.t) * uniform(1.3, 2.1);
    crawl_factor_ = uniform(1.0, 1.25);
    slip_left_ = uniform(0.8, 2.5);
    state_.gear = 1;
    state_.clutch = Clutch::kSlipping;
  }

  void start_shift(int to) {
    phase_ = Phase::kShift;
    shift_to_ = std::clamp(to, 1, veh_.gears());
    // Clutch-out time of a manual shift: 0.3-1.5 s, mostly short.
    shift_left_ = 0.3 + 1.2 * std::pow(uniform(0, 1), 2.0);
    shift_tau_ = uniform(0.15, 0.5);
    shift_to_idle_ = uniform(0, 1) < 0.3;
    upshift_point_ = veh_.upshift_freq * uniform(0.8, 1.35);
    cruise_margin_ = uniform(1.05, 1.4);
    state_.gear = 0;
    state_.clutch = Clutch::kDisengaged;
  }

  int lowest_comfortable_gear(double idle) const {
    // The highest gear that keeps the engine comfortably above idle.
    int best = 1;
    for (int g = 1; g <= veh_.gears(); ++g) {
      if (state_.v / veh_.theta[g - 1] > std::max(idle * 1.3, veh_.downshift_freq * 1.05)) best = g;
    }
    return best;
  }

  const Vehicle& veh_;
  std::mt19937_64 rng_;
  RouteGenerator route_;
  State state_;
  Phase phase_ = Phase::kStand;
  Leg leg_;
  bool stopping_ = true;  // start parked
  double stand_left_ = 0.0;
  double brake_ = 1.5;
  double coast_speed_ = 3.0;
  double aggressiveness_ = 1.0;
  double launch_freq_ = 20.0;
  double crawl_factor_ = 1.1;
  double slip_left_ = 1.5;
  double cold_start_ = 0.0;
  double warm_up_ = 1.0;  // set from DriveOptions
  double skip_downshift_ = 0.0;
  double idle_wobble_ = 0.0;
  double jitter_ = 0.0;
  int shift_to_ = 1;
  double shift_left_ = 0.0;
  double shift_tau_ = 0.3;
  bool shift_to_idle_ = false;
  double upshift_point_ = 40.0;
  double cruise_margin_ = 1.2;
  double cvt_f_ = 20.0;
};

TruthSample to_truth(const State& s) {
  return {s.t, s.v, s.f, s.gear, s.clutch};
}

TruthSample interpolate(const State& a, const State& b, double t) {
  const double w = b.t > a.t ? std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0) : 0.0;
  TruthSample out = to_truth(a);
  out.t = t;
  out.speed = a.v + w * (b.v - a.v);
  out.freq = a.f + w * (b.f - a.f);
  return out;
}

void check_vehicle(const Vehicle& v) {
  if (v.is_cvt()) {
    if (!(v.cvt_theta_min > 0.0 && v.cvt_theta_max > v.cvt_theta_min))
      throw std::invalid_argument("vehicle '" + v.name + "': CVT needs 0 < cvt_theta_min < cvt_theta_max");
  } else {
    for (std::size_t i = 0; i < v.theta.size(); ++i) {
      if (!(v.theta[i] > 0.0) || (i > 0 && !(v.theta[i] > v.theta[i - 1])))
        throw std::invalid_argument("vehicle '" + v.name + "': theta must be positive and ascending");
    }
  }
  if (!(v.idle_freq > 0.0 && v.max_freq > v.idle_freq * 2.0))
    throw std::invalid_argument("vehicle '" + v.name + "': need 0 < 2 * idle_freq < max_freq");
}

}  // namespace

Drive simulate_drive(const Vehicle& vehicle, const DriveOptions& options) {
  check_vehicle(vehicle);
  if (!(options.dt > 0.0) || !(options.duration >= 0.0) || options.duration / options.dt > 1e9)
    throw std::invalid_argument("simulate_drive: need dt > 0 and duration >= 0");
  if (!(options.cold_start >= 0.0 && options.cold_start <= 2.0) || !(options.warm_up > 0.0))
    throw std::invalid_argument("simulate_drive: need 0 <= cold_start <= 2 and warm_up > 0");
  Drive drive{vehicle, options, {}};
  const auto count = static_cast<std::size_t>(std::floor(options.duration / options.dt + 1e-9)) + 1;
  drive.truth.reserve(count);
  DriveSimulator sim(drive.vehicle, options);
  State prev = sim.state();
  std::size_t k = 0;
  while (k < count) {
    const double t_out = static_cast<double>(k) * options.dt;
    if (t_out <= sim.state().t + 1e-12) {
      drive.truth.push_back(interpolate(prev, sim.state(), t_out));
      ++k;
      continue;
    }
    prev = sim.state();
    sim.step();
  }
  return drive;
}

TruthSample truth_at(const Drive& drive, double t) {
  if (drive.truth.empty()) return {};
  const double dt = drive.options.dt;
  const double pos = std::clamp(t / dt, 0.0, static_cast<double>(drive.truth.size() - 1));
  const auto i = static_cast<std::size_t>(std::floor(pos));
  const TruthSample& a = drive.truth[i];
  if (i + 1 >= drive.truth.size()) return a;
  const TruthSample& b = drive.truth[i + 1];
  const double w = pos - static_cast<double>(i);
  TruthSample out = a;
  out.t = t;
  out.speed = a.speed + w * (b.speed - a.speed);
  out.freq = a.freq + w * (b.freq - a.freq);
  return out;
}

}  // namespace gearpulse::sim
