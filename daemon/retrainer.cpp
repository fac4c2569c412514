#include "daemon/retrainer.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <exception>
#include <optional>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "common/atomic_file.hpp"
#include "core/estimator.hpp"
#include "daemon/fitter.hpp"
#include "daemon/state_directory.hpp"
#include "drivers/clock.hpp"

namespace gearpulse::daemon {
namespace {

// A fit may take a second of CPU on a week of data; the capture, tracker and pulse threads must not
// notice, so the fit runs in a thread of its own that only runs when nothing else wants the CPU. Only the
// fit: that thread holds no lock another thread waits on (the store's copy, the model's installation and
// its save, the log are done at normal priority, where a busy CPU cannot hold them up for seconds).
GearModel fit_at_low_priority(const std::function<GearModel()>& fit) {
  GearModel fitted;
  std::exception_ptr failure;
  std::thread worker([&]() noexcept {
    const auto tid = static_cast<id_t>(::syscall(SYS_gettid));
    (void)::setpriority(PRIO_PROCESS, tid, 19);
    sched_param param{};
    (void)pthread_setschedparam(pthread_self(), SCHED_IDLE, &param);  // else nice 19 stands
    try {
      fitted = fit();
    } catch (...) {
      failure = std::current_exception();
    }
  });
  worker.join();
  if (failure) std::rethrow_exception(failure);
  return fitted;
}

}  // namespace

Retrainer::Retrainer(TrainingStore& store, ModelHolder& model, std::filesystem::path model_path,
                     Fitter fitter, Settings settings)
    : store_(store),
      model_(model),
      model_path_(std::move(model_path)),
      fitter_(std::move(fitter)),
      settings_(settings),
      schedule_(settings.learning) {
  status_.young = young_ = settings.learning.young_time > 0.0;
}

Retrainer::~Retrainer() {
  stop();
}

void Retrainer::start() {
  {
    std::lock_guard lock(mutex_);
    stop_ = false;
    fit_stop_ = std::stop_source();
  }
  thread_ = std::thread([this] { run(); });
}

void Retrainer::stop() noexcept {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
    fit_stop_.request_stop();
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void Retrainer::request() noexcept {
  {
    std::lock_guard lock(mutex_);
    requested_ = true;
  }
  wake_.notify_all();
}

void Retrainer::set_settings(Settings settings) noexcept {
  {
    std::lock_guard lock(mutex_);
    settings_ = settings;
    schedule_.set_settings(settings.learning);
    young_ = true;  // the next look decides under the new schedule
  }
  wake_.notify_all();
}

Retrainer::Settings Retrainer::settings() const {
  std::lock_guard lock(mutex_);
  return settings_;
}

Retrainer::Status Retrainer::status() const {
  std::lock_guard lock(mutex_);
  Status now = status_;
  now.save_problem = save_fault_.what();
  return now;
}

bool Retrainer::retrain_now() {
  const std::uint64_t generation = model_.generation();
  const std::uint64_t clears = store_.clears();  // read first: a clear after it keeps the pairs new
  const std::size_t fresh = store_.new_samples();
  std::vector<Sample> samples;
  bool no_ladder_before = false;
  std::stop_token stop;
  {
    std::lock_guard lock(mutex_);
    no_ladder_before = no_ladder_;
    stop = fit_stop_.get_token();
    status_.busy = true;
    ++status_.runs;
    status_.last_run_wall = wall_now();
  }
  std::string result;
  bool changed = false;
  bool no_ladder = false;
  // What the journal is told of this fit: said after the status holds its result, so whoever reads the
  // line and then asks for status finds the fit there.
  spdlog::level::level_enum said_level = spdlog::level::info;
  std::string said;
  try {
    samples = store_.snapshot();  // up to max_samples pairs: a copy that may not find the memory
    if (samples.empty()) {
      result = "no training samples yet";
    } else {
      const auto t0 = std::chrono::steady_clock::now();
      // A refit keeps the gears of the model in use that its pairs do not contradict.
      const ModelPtr before = model_.get();
      const std::size_t judge_pairs = settings().learning.cluster_pairs;
      std::size_t kept = 0;
      bool withdraw = false;
      GearModel fitted = fit_at_low_priority([&] {
        GearModel fit = fitter_(samples, stop);
        if (before && fit.empty()) withdraw = one_gear_withdrawn(*before, samples);
        if (!before || before->empty() || fit.empty()) return fit;
        const std::size_t found = fit.gears.size();
        fit = keep_seen_gears(*before, std::move(fit), samples, judge_pairs);
        kept = fit.gears.size() - found;
        return fit;
      });
      const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (fitted.empty() && withdraw) {
        result = withdraw_model(samples.size(), generation);
        said_level = spdlog::level::warn;
        said = "retrain: " + result;
        no_ladder = true;
      } else if (fitted.empty()) {
        result = fmt::format("fit on {} samples found no gear ladder ({}); model kept", samples.size(),
                             fitted.reason.empty() ? "no reason given" : fitted.reason);
        // An automatic gives this answer at every retrain: a warning the first time, then a note.
        no_ladder = true;
        if (no_ladder_before) {
          said = fmt::format("retrain: {} (as at the last attempt)", result);
        } else {
          said_level = spdlog::level::warn;
          said = "retrain: " + result;
        }
      } else if (const ModelPtr current = model_.get();
                 current && !current->empty() && fitted.samples < replace_threshold(*current)) {
        result = fmt::format(
            "fit on {} samples found {} gears; current model (fitted on {} samples) kept until a fit uses {}",
            fitted.samples, fitted.gears.size(), current->samples, replace_threshold(*current));
        said = "retrain: " + result;
      } else if (auto lock = model_.lock_writes(); model_.generation() != generation) {
        result = fmt::format("fit on {} samples discarded: the model was replaced or reset during the fit",
                             samples.size());
        said = "retrain: " + result;
      } else {
        const std::size_t gears = fitted.gears.size();
        // The newest pair it saw: pairs after it are new to the model at the next start too.
        double newest = samples.front().t;
        for (const Sample& s : samples)
          newest = std::max(newest, s.t);
        fitted.extra[std::string(kTrainedUntil)] = newest;
        fitted.extra[std::string(kTrainedLast)] = {samples.back().t, samples.back().speed,
                                                   samples.back().freq};
        auto next = std::make_shared<const GearModel>(std::move(fitted));
        model_.set(next);
        changed = true;
        result = fmt::format("fit on {} samples: {} gears{} in {:.2f} s", samples.size(), gears,
                             kept > 0 ? fmt::format(" ({} kept from the model before)", kept) : "", secs);
        // A pair is stamped receive time - gps.latency; a fit that finds its GPS speed describing the
        // engine lag s before that stamp (speed_lag > 0) says the latency is longer than set by about
        // that much. The fit moved the speeds itself, and the synthesis takes the lag out of each fix
        // counted from its stamp (SpeedLag). Lags under kLagWorthSaying are within what the search
        // resolves at 1 Hz.
        constexpr double kLagWorthSaying = 0.1;  // s
        if (const double lag = next->extra.value("speed_lag", 0.0); std::abs(lag) >= kLagWorthSaying)
          result += fmt::format(
              " (the GPS speeds describe the engine {:.2f} s {} their stamps: gps.latency may be "
              "{:.2f} s too {})",
              std::abs(lag), lag > 0.0 ? "before" : "after", std::abs(lag), lag > 0.0 ? "short" : "long");
        said = fmt::format("retrain: {}; new model in use", result);
        save_fitted(*next, result);
      }
    }
    store_.mark_trained(fresh, clears);
  } catch (const FitCancelled&) {
    // Not a failure: the pairs stay new, so the next start fits them.
    result = "fit cancelled: gearpulsed is stopping; model kept";
    said = "retrain: " + result;
  } catch (const std::exception& e) {
    result = std::string("fit failed: ") + e.what() + "; model kept";
    said_level = spdlog::level::err;
    said = "retrain: " + result;
    store_.mark_trained(fresh, clears);
  } catch (...) {
    // Not a std::exception (a fitter's own type): the retrainer's thread must not end the daemon for it.
    result = "fit failed: an exception of unknown type; model kept";
    said_level = spdlog::level::err;
    said = "retrain: " + result;
    store_.mark_trained(fresh, clears);
  }
  {
    std::lock_guard lock(mutex_);
    status_.busy = false;
    status_.last_result = result;
    no_ladder_ = no_ladder;
    if (changed) ++status_.accepted;
  }
  if (!said.empty()) spdlog::log(said_level, "{}", said);
  return changed;
}

void Retrainer::save_fitted(const GearModel& fitted, std::string& result) {
  std::string unsaved;  // why model.json does not hold the fit
  bool replaced = false;
  try {
    replaced = save_model_if_ours(model_, model_path_, fitted) == ModelSave::kReplacedByOther;
    if (replaced) unsaved = "model.json was replaced by another program";
  } catch (const std::exception& e) {
    unsaved = e.what();
  }
  bool news = false;  // the spell of failed saves starts, changes or ends: said at the level it merits
  {
    std::lock_guard lock(mutex_);
    if (unsaved.empty())
      news = save_fault_.succeeded();
    else
      // A disk that stays full or read-only fails every retrain the same way: said when that starts or
      // changes (status lists it meanwhile), not at every retrain.
      news =
          save_fault_.failed(replaced ? "fits not saved: model.json was replaced by another program (it is "
                                        "loaded at the next start)"
                                      : "cannot save model.json: " + unsaved);
  }
  if (unsaved.empty()) {
    if (news) spdlog::info("retrain: {} saved again", model_path_.string());
    return;
  }
  result += "; not saved: " + unsaved;
  if (!news)
    spdlog::debug("retrain: {} not saved, as at the last fit: {}", model_path_.string(), unsaved);
  else if (replaced)
    spdlog::warn(
        "retrain: {} was replaced while gearpulsed ran; left as it is (it is loaded at the next start), so "
        "fits are not saved until then",
        model_path_.string());
  else
    spdlog::error("retrain: cannot save {}: {}; the new model is used but will be lost at restart; {}",
                  model_path_.string(), unsaved, state_dir_advice(model_path_.parent_path()));
}

void Retrainer::model_file_removed() noexcept {
  std::lock_guard lock(mutex_);
  (void)save_fault_.succeeded();
}

std::size_t Retrainer::replace_threshold(const GearModel& current) const {
  // A fit on every pair the store can hold is the most the car can give: a model fitted on more (by
  // `gearpulse fit` on days of logs, or before the store's limits were lowered) would otherwise never be
  // replaced.
  return std::min({current.samples, settings().replace_min_samples, store_.capacity()});
}

void Retrainer::model_reset(bool pairs_cleared) noexcept {
  std::lock_guard lock(mutex_);
  (void)save_fault_.succeeded();
  // The fits tried were on pairs, or against a model, that are gone: a schedule that remembered them
  // would wait for a refit time or a cluster larger than theirs, the interval rule for its next end.
  schedule_.restart();
  young_ = true;
  if (!pairs_cleared) requested_ = true;
  wake_.notify_all();
}

std::string Retrainer::withdraw_model(std::size_t pairs, std::uint64_t generation) {
  const auto lock = model_.lock_writes();
  if (model_.generation() != generation)
    return fmt::format("fit on {} samples discarded: the model was replaced or reset during the fit", pairs);
  model_.set(nullptr);
  std::string result = fmt::format(
      "fit on {} samples found no gear ladder, and the steady pairs beside the model's one gear are a "
      "continuum (as from a CVT below its cruise ratio): that gear is withdrawn, pulses follow GPS",
      pairs);
  // A model.json another program installed while the daemon ran is not the one withdrawn: it stays, to
  // be loaded at the next start, as a fit's save leaves it (save_model_if_ours).
  if (const std::optional<FileStamp> now = stamp_of(model_path_); now && now != model_.file_stamp())
    return result +
           fmt::format("; {} was replaced while gearpulsed ran and is left as it is", model_path_.string());
  try {
    remove_file_durable(model_path_);
    model_.set_file_stamp(std::nullopt);
    model_file_removed();
  } catch (const std::exception& e) {
    result += fmt::format("; {} stays until the next fit: {}", model_path_.string(), e.what());
  }
  return result;
}

bool Retrainer::schedule_due(std::unique_lock<std::mutex>& lock) {
  lock.unlock();
  std::optional<PairsSummary> pairs;
  const ModelPtr model = model_.get();
  try {
    pairs = summarize_pairs(store_.snapshot(), model.get());  // while young, minutes of pairs: a small copy
  } catch (...) {
    // No memory for the copy: the schedule looks again next time.
  }
  const bool has_model = model && !model->empty();
  const std::size_t size = store_.size();
  lock.lock();
  if (!pairs) return false;
  looked_ = *pairs;
  young_ = schedule_.young(*pairs, has_model);
  if (!young_) settled_size_ = size;
  status_.young = young_;
  status_.moving_time = pairs->moving_time;
  status_.cluster_pairs = pairs->largest_cluster;
  status_.next_refit = young_ ? schedule_.next_refit(pairs->moving_time).value_or(-1.0) : -1.0;
  return schedule_.due(*pairs, has_model);
}

void Retrainer::run() noexcept {
  using Clock = std::chrono::steady_clock;
  // While young the schedule looks at the store this often: pairs come at about 1 Hz, and its refit
  // times are a minute of moving and more apart.
  constexpr double kLearningLook = 5.0;  // s
  // Each look copies the store and reads it once: a store of hours of standing pairs (a car idling with
  // GPS, a young model all the same) is looked at less often, at most this many pairs a second on average.
  constexpr double kLookPairsPerSecond = 4000.0;
  std::unique_lock lock(mutex_);
  // At start, learn right away rather than after a full interval when there is something to learn from:
  // a restored store and no model yet, or enough pairs the model has not seen (gathered on trips shorter
  // than the interval, which would otherwise never reach it).
  bool first = true;
  Clock::time_point interval_start = Clock::now();
  const auto interval_end = [&] {
    return interval_start + std::chrono::duration_cast<Clock::duration>(settings_.interval);
  };
  while (!stop_) {
    if (!first && !requested_) {
      // The interval as set now: a reload that shortens it wakes this wait, which then ends at the new
      // deadline rather than the old one.
      const double look_s = std::max(kLearningLook, static_cast<double>(store_.size()) / kLookPairsPerSecond);
      const auto look =
          Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(look_s));
      while (!stop_ && !requested_) {
        const auto deadline = young_ ? std::min(interval_end(), look) : interval_end();
        if (Clock::now() >= deadline) break;
        wake_.wait_until(lock, deadline);
      }
      if (stop_) break;
    }
    const bool forced = requested_;
    requested_ = false;
    bool due = false;
    if (first || Clock::now() >= interval_end()) {
      interval_start = Clock::now();
      const std::size_t needed = settings_.min_new_samples;
      due = first && !model_.trained() ? store_.size() >= needed : store_.new_samples() >= needed;
    }
    first = false;
    if (!young_ && store_.size() < settled_size_) {  // the pairs were cleared: learn as new
      young_ = true;
      schedule_.restart();
    }
    if (young_ && schedule_due(lock)) due = true;
    if (stop_) break;
    if (!forced && !due) continue;
    if (young_) schedule_.tried(looked_);
    lock.unlock();
    try {
      retrain_now();
    } catch (...) {
      // Only the bookkeeping around a failed fit can get here (no memory left to say why): the model is
      // kept, and the next interval tries again.
      spdlog::error("retrain: failed without a report (out of memory?); model kept");
    }
    lock.lock();
    status_.busy = false;
  }
}

}  // namespace gearpulse::daemon
