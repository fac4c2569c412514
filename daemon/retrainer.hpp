#pragma once
// Periodic retraining in a low-priority thread (nice 19, SCHED_IDLE): fits a new gear model on the
// training store and swaps it in atomically. Pulses never wait for it; an empty fit (no gear ladder)
// or a failed one never replaces a good model, and a refit keeps the gears it lacks that its pairs do not
// contradict (keep_seen_gears). While the model is young the learning schedule decides when to fit
// (learning_schedule.hpp), then every interval with min_new_samples new pairs.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <span>
#include <stop_token>
#include <string>
#include <string_view>
#include <thread>

#include "core/gear_model.hpp"
#include "core/sample.hpp"
#include "daemon/learning_schedule.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/model_store.hpp"
#include "daemon/training_store.hpp"

namespace gearpulse::daemon {

// Key in a model's `extra` object the daemon's fits carry: the wall-clock time (UNIX s) of the newest
// training pair the fit saw. Pairs after it count as new for the next retrain, across restarts, for a
// model without kTrainedLast (or whose last pair has left the store).
inline constexpr std::string_view kTrainedUntil = "trained_until";
// And the last pair it saw in the store's order, [t, speed, freq]: the pairs after it in the store are
// new, whatever the wall clock said when either was made (a car PC's clock may be years off until set).
inline constexpr std::string_view kTrainedLast = "trained_last";

class Retrainer {
 public:
  // Fits a model on the samples; an empty model (gears empty, reason set) means "no ladder". A fit told to
  // stop (the daemon is stopping) may end early by throwing FitCancelled.
  using Fitter = std::function<GearModel(std::span<const Sample>, std::stop_token)>;

  struct Settings {
    std::chrono::duration<double> interval{600.0};
    std::size_t min_new_samples = 600;
    // A fit on fewer samples than this (and than the current model's, and than the store holds at most)
    // does not replace a trained model: ten minutes in town must not overwrite a ladder learned over days.
    std::size_t replace_min_samples = 3600;
    LearningSettings learning{};
  };

  struct Status {
    std::uint64_t runs = 0;      // fits attempted
    std::uint64_t accepted = 0;  // fits that replaced the model
    double last_run_wall = 0.0;  // UNIX seconds of the last attempt, 0 = never
    std::string last_result;     // one line for status
    std::string save_problem;    // why fits are not saved to model.json, while they are not ("" else)
    bool busy = false;
    bool young = false;             // the learning schedule decides the fits
    double moving_time = 0.0;       // s of moving the training pairs covered at the schedule's last look
    double next_refit = -1.0;       // s of moving at the schedule's next refit, -1 = none
    std::size_t cluster_pairs = 0;  // steady pairs in the densest gear window at that look
  };

  Retrainer(TrainingStore& store, ModelHolder& model, std::filesystem::path model_path, Fitter fitter,
            Settings settings);
  ~Retrainer();
  Retrainer(const Retrainer&) = delete;
  Retrainer& operator=(const Retrainer&) = delete;

  void start();
  // Ends the thread, cancelling a fit under way (its pairs stay new for the next start's fit).
  void stop() noexcept;
  // Fit as soon as possible, whatever the count of new samples.
  void request() noexcept;
  // Takes effect at once, a wait under way included (it ends at the new interval).
  void set_settings(Settings settings) noexcept;
  // model.json was removed (a reset): a failure to save over it is over, and the next fit's save says anew.
  void model_file_removed() noexcept;
  // The model was reset (reset-model, after StateDirectory::reset_model): model.json is gone, and the
  // learning schedule starts again at once: with the pairs cleared as for a new car, with them kept by a
  // fit on them as soon as possible.
  void model_reset(bool pairs_cleared) noexcept;
  [[nodiscard]] Status status() const;
  [[nodiscard]] Settings settings() const;
  // Runs one retrain now (what the thread does): the store's copy, the model's installation and its save on
  // the calling thread, the fit itself in a thread of its own at the lowest priority; returns true if the
  // model changed to a new fit.
  bool retrain_now();

 private:
  void run() noexcept;
  // The schedule's look at the store (under mutex_ when called; released for the copy): whether a fit is
  // due by it. Sets young_ and the status' schedule fields.
  bool schedule_due(std::unique_lock<std::mutex>& lock);
  // Withdraws a one-gear model a fit on `pairs` pairs found without ground (one_gear_withdrawn), unless
  // the model changed since `generation`; returns the result line.
  std::string withdraw_model(std::size_t pairs, std::uint64_t generation);
  // The fewest samples a fit needs to replace `current` (Settings::replace_min_samples).
  [[nodiscard]] std::size_t replace_threshold(const GearModel& current) const;
  // Saves a fit just installed (under model_.lock_writes()) unless model.json was replaced by another
  // program; says why not in `result`, and in the log and status while saves keep failing (save_fault_).
  void save_fitted(const GearModel& fitted, std::string& result);

  TrainingStore& store_;
  ModelHolder& model_;
  std::filesystem::path model_path_;
  Fitter fitter_;

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  Settings settings_;
  Status status_;
  bool no_ladder_ = false;  // the last fit found no gear ladder
  FaultSpell save_fault_;   // fits not saved to model.json (status' save_problem)
  LearningSchedule schedule_;
  bool young_ = true;             // the schedule may decide fits: the thread looks at the store often
  std::size_t settled_size_ = 0;  // store size when the schedule ended; a smaller store starts it again
  PairsSummary looked_;           // the pairs at the schedule's last look
  bool requested_ = false;
  bool stop_ = false;
  std::stop_source fit_stop_;  // requested by stop(): a fit under way ends at its next pass over the pairs
  std::thread thread_;
};

}  // namespace gearpulse::daemon
