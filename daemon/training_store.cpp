#include "daemon/training_store.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <exception>

#include "common/atomic_file.hpp"

namespace gearpulse::daemon {
namespace {

constexpr char kMagic[8] = {'G', 'P', 'T', 'R', 'A', 'I', 'N', '\n'};
constexpr std::uint32_t kVersion = 1;
constexpr std::uint32_t kRecordSize = 3 * sizeof(double);
constexpr std::size_t kHeaderSize = sizeof kMagic + 2 * sizeof(std::uint32_t) + sizeof(std::uint64_t);
constexpr char kJournalMagic[8] = {'G', 'P', 'J', 'O', 'U', 'R', 'N', '\n'};
constexpr std::size_t kJournalHeaderSize = sizeof kJournalMagic + 2 * sizeof(std::uint32_t);
constexpr std::size_t kJournalRecordSize = kRecordSize + sizeof(std::uint32_t);

template <typename T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

template <typename T>
T get(std::string_view in, std::size_t offset) {
  T value;
  std::memcpy(&value, in.data() + offset, sizeof(T));
  return value;
}

// The checksum a saved store ends with (what a journal names as the file it extends); 0 for none.
std::uint32_t trailing_crc(std::string_view blob) {
  return blob.size() >= sizeof(std::uint32_t) ? get<std::uint32_t>(blob, blob.size() - sizeof(std::uint32_t))
                                              : 0;
}

void put_record(std::string& out, const Sample& s) {
  put(out, s.t);
  put(out, s.speed);
  put(out, s.freq);
}

Sample get_record(std::string_view in, std::size_t offset) {
  return {get<double>(in, offset), get<double>(in, offset + 8), get<double>(in, offset + 16)};
}

bool plausible(const Sample& s) {
  return std::isfinite(s.t) && std::isfinite(s.speed) && std::isfinite(s.freq) && s.speed >= 0.0 &&
         s.freq > 0.0;
}

}  // namespace

std::uint32_t crc32(std::string_view data) noexcept {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k)
        c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t crc = 0xFFFFFFFFu;
  for (unsigned char byte : data)
    crc = table[(crc ^ byte) & 0xFFu] ^ (crc >> 8);
  return crc ^ 0xFFFFFFFFu;
}

TrainingStore::TrainingStore(double max_age_s, std::size_t max_samples)
    : max_age_s_(max_age_s), max_samples_(max_samples) {}

double TrainingStore::step(const Sample& a, const Sample& b) noexcept {
  return std::min(std::abs(b.t - a.t), kMaxStepS);
}

void TrainingStore::push_back_locked(const Sample& s) {
  if (!samples_.empty()) span_s_ += step(samples_.back(), s);
  samples_.push_back(s);
}

void TrainingStore::pop_front_locked() noexcept {
  if (samples_.size() >= 2) span_s_ -= step(samples_[0], samples_[1]);
  samples_.pop_front();
  if (samples_.size() <= 1) span_s_ = 0.0;
}

bool TrainingStore::add(const Sample& sample) {
  if (!plausible(sample)) return false;
  std::lock_guard lock(mutex_);
  push_back_locked(sample);
  ++new_samples_;
  ++since_save_;
  ++unjournaled_;
  enforce_bounds_locked();
  return true;
}

void TrainingStore::set_limits(double max_age_s, std::size_t max_samples) {
  std::lock_guard lock(mutex_);
  max_age_s_ = max_age_s;
  max_samples_ = max_samples;
  enforce_bounds_locked();
}

void TrainingStore::clear() {
  std::lock_guard lock(mutex_);
  empty_locked();
  cleared_ = true;
}

void TrainingStore::empty_locked() noexcept {
  samples_.clear();
  span_s_ = 0.0;
  new_samples_ = since_save_ = unjournaled_ = skipped_ = 0;
}

std::vector<Sample> TrainingStore::snapshot() const {
  std::lock_guard lock(mutex_);
  return {samples_.begin(), samples_.end()};
}

std::size_t TrainingStore::size() const {
  std::lock_guard lock(mutex_);
  return samples_.size();
}

std::size_t TrainingStore::unkept() const {
  std::lock_guard lock(mutex_);
  // A journal that is not current is rewritten whole at the next append: count every pair since the save.
  return journal_current_ ? unjournaled_ : since_save_;
}

bool TrainingStore::unsaved() const {
  std::lock_guard lock(mutex_);
  return since_save_ > 0 || cleared_;
}

std::size_t TrainingStore::new_samples() const {
  std::lock_guard lock(mutex_);
  return new_samples_;
}

void TrainingStore::mark_trained(std::size_t consumed) {
  std::lock_guard lock(mutex_);
  new_samples_ -= std::min(consumed, new_samples_);
}

bool TrainingStore::set_new_after_pair(const Sample& last) {
  std::lock_guard lock(mutex_);
  for (std::size_t i = samples_.size(); i-- > 0;) {
    const Sample& s = samples_[i];
    if (s.t == last.t && s.speed == last.speed && s.freq == last.freq) {
      new_samples_ = samples_.size() - i - 1;
      return true;
    }
  }
  return false;
}

void TrainingStore::set_new_after(double t) {
  std::lock_guard lock(mutex_);
  new_samples_ = static_cast<std::size_t>(
      std::count_if(samples_.begin(), samples_.end(), [t](const Sample& s) { return s.t > t; }));
}

void TrainingStore::enforce_bounds_locked() {
  // Age is the driving time since a pair, not the wall clock's: pairs older than max_age of driving fall
  // off the front. (Judged against the newest pair's time, a weekend parked or a clock set forward
  // emptied the store at the first new pair, and a pair stamped in the future stopped all pruning.)
  while (samples_.size() > 1 && span_s_ > max_age_s_)
    pop_front_locked();
  while (samples_.size() > max_samples_)
    pop_front_locked();
  clamp_counts_locked();
}

// Counts of pairs at the back of samples_ cannot exceed what is left after pairs fell off the front.
void TrainingStore::clamp_counts_locked() noexcept {
  new_samples_ = std::min(new_samples_, samples_.size());
  since_save_ = std::min(since_save_, samples_.size());
  unjournaled_ = std::min(unjournaled_, samples_.size());
}

std::size_t TrainingStore::skipped() const {
  std::lock_guard lock(mutex_);
  return skipped_;
}

std::string TrainingStore::serialize() const {
  std::lock_guard lock(mutex_);
  return serialize_locked();
}

std::string TrainingStore::serialize_locked() const {
  std::string out;
  out.reserve(kHeaderSize + samples_.size() * kRecordSize + sizeof(std::uint32_t));
  out.append(kMagic, sizeof kMagic);
  put(out, kVersion);
  put(out, kRecordSize);
  put(out, static_cast<std::uint64_t>(samples_.size()));
  for (const Sample& s : samples_)
    put_record(out, s);
  put(out, crc32(out));
  return out;
}

std::string TrainingStore::deserialize(std::string_view blob) {
  {
    std::lock_guard lock(mutex_);
    empty_locked();
  }
  if (blob.size() < kHeaderSize + sizeof(std::uint32_t))
    return "file too short (" + std::to_string(blob.size()) + " bytes)";
  if (std::memcmp(blob.data(), kMagic, sizeof kMagic) != 0) return "not a training store (bad magic)";
  const auto version = get<std::uint32_t>(blob, sizeof kMagic);
  if (version != kVersion) return "unsupported version " + std::to_string(version);
  const auto record = get<std::uint32_t>(blob, sizeof kMagic + 4);
  if (record != kRecordSize) return "unexpected record size " + std::to_string(record);
  const auto count = get<std::uint64_t>(blob, sizeof kMagic + 8);
  const std::size_t body = blob.size() - kHeaderSize - sizeof(std::uint32_t);
  if (count > body / kRecordSize || count * kRecordSize != body)
    return "truncated or padded: header says " + std::to_string(count) + " records, file holds " +
           std::to_string(body) + " bytes";
  const std::size_t crc_at = blob.size() - sizeof(std::uint32_t);
  if (get<std::uint32_t>(blob, crc_at) != crc32(blob.substr(0, crc_at))) return "checksum mismatch";
  std::deque<Sample> loaded;
  std::size_t skipped = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t at = kHeaderSize + i * kRecordSize;
    const Sample s = get_record(blob, at);
    // The checksum holds, so the record is where the header says and the others are sound: one bad
    // pair (written by another program, or corrupted before the checksum was taken) costs only itself.
    if (!plausible(s)) {
      ++skipped;
      continue;
    }
    loaded.push_back(s);
  }
  std::lock_guard lock(mutex_);
  skipped_ = skipped;
  samples_ = std::move(loaded);
  span_s_ = 0.0;
  for (std::size_t i = 1; i < samples_.size(); ++i)
    span_s_ += step(samples_[i - 1], samples_[i]);
  new_samples_ = 0;
  enforce_bounds_locked();
  return {};
}

void TrainingStore::save(const std::filesystem::path& path) {
  std::lock_guard io(io_mutex_);
  std::string blob;
  std::size_t saved = 0, unjournaled = 0;
  bool cleared = false;
  std::exception_ptr unsynced;
  {
    // What the blob holds needs no journal; pairs added from here on do.
    std::lock_guard lock(mutex_);
    blob = serialize_locked();
    saved = since_save_;
    unjournaled = unjournaled_;
    cleared = cleared_;
    since_save_ = unjournaled_ = 0;
    cleared_ = false;
  }
  try {
    // After a clear() the old journal goes first: an empty store's file is the same bytes every time, so
    // a journal naming an earlier empty file would otherwise bring back pairs cleared since.
    if (cleared) {
      remove_file_durable(journal_path(path));
      std::lock_guard lock(mutex_);
      journal_current_ = false;
    }
    try {
      write_file_atomic(path, blob);
    } catch (const DirectorySyncError&) {
      // The new file is the one in place: the bookkeeping is that of a save (a journal from now on must
      // name it), and the error is still said once it is done (the caller tries again).
      unsynced = std::current_exception();
    }
  } catch (...) {
    // The previous file stands, and so does its journal unless it was removed (then it is rewritten
    // whole); the pairs are still to be saved (and journaled).
    std::lock_guard lock(mutex_);
    since_save_ = std::min(since_save_ + saved, samples_.size());
    unjournaled_ = std::min(unjournaled_ + unjournaled, samples_.size());
    cleared_ = cleared_ || cleared;
    throw;
  }
  {
    std::lock_guard lock(mutex_);
    saved_crc_ = trailing_crc(blob);
    journal_current_ = false;
    unjournaled_ = since_save_;
  }
  // The old journal names the old file and would be ignored; a fresh one is started now rather than at
  // the next append. If this fails, the next append tries again.
  try {
    append_journal_io(path);
  } catch (const std::exception&) {
  }
  if (unsynced) std::rethrow_exception(unsynced);
}

std::string TrainingStore::load(const std::filesystem::path& path) {
  {
    std::lock_guard lock(mutex_);
    saved_crc_ = 0;
    journal_current_ = false;
  }
  const auto blob = read_file(path, static_cast<std::size_t>(file_bytes(kMaxStoreSamples)));
  std::string problem = blob ? deserialize(*blob) : std::string();
  std::lock_guard lock(mutex_);
  if (!blob) empty_locked();
  // A journal extends a file that loaded; one written after a corrupt file (set aside by the caller)
  // extends none, as does one of a first run that never saved.
  if (blob && problem.empty()) saved_crc_ = trailing_crc(*blob);
  return problem;
}

double TrainingStore::file_bytes(std::size_t pairs) noexcept {
  return static_cast<double>(kHeaderSize + sizeof(std::uint32_t)) +
         static_cast<double>(pairs) * static_cast<double>(kRecordSize);
}

std::filesystem::path TrainingStore::journal_path(const std::filesystem::path& path) {
  std::filesystem::path journal = path;
  journal += ".journal";
  return journal;
}

std::size_t TrainingStore::append_journal(const std::filesystem::path& path) {
  std::lock_guard io(io_mutex_);
  return append_journal_io(path);
}

std::size_t TrainingStore::append_journal_io(const std::filesystem::path& path) {
  std::string out;
  std::size_t count = 0;
  bool rewrite = false;
  {
    std::lock_guard lock(mutex_);
    rewrite = !journal_current_;
    count = rewrite ? since_save_ : unjournaled_;
    if (!rewrite && count == 0) return 0;
    if (rewrite) {
      out.append(kJournalMagic, sizeof kJournalMagic);
      put(out, kVersion);
      put(out, saved_crc_);
    }
    for (auto it = samples_.end() - static_cast<std::ptrdiff_t>(count); it != samples_.end(); ++it) {
      const std::size_t at = out.size();
      put_record(out, *it);
      put(out, crc32(std::string_view(out).substr(at)));
    }
    unjournaled_ = 0;
    journal_current_ = true;
  }
  try {
    if (rewrite)
      write_file_atomic(journal_path(path), out);
    else
      append_file_durable(journal_path(path), out);
  } catch (...) {
    // A failed append may have left part of a record: the journal is rewritten whole next time.
    std::lock_guard lock(mutex_);
    journal_current_ = false;
    unjournaled_ = since_save_;
    throw;
  }
  return count;
}

TrainingStore::JournalReplay TrainingStore::replay_journal(const std::filesystem::path& path) {
  JournalReplay replay;
  // A journal holds at most the pairs since the last save, never more than the store does.
  const auto blob = read_file(journal_path(path), kJournalHeaderSize + kMaxStoreSamples * kJournalRecordSize);
  if (!blob) return replay;
  if (blob->empty()) {
    replay.problem = "empty (nothing to recover)";
    return replay;
  }
  if (blob->size() < kJournalHeaderSize ||
      std::memcmp(blob->data(), kJournalMagic, sizeof kJournalMagic) != 0) {
    replay.problem = "not a training journal (bad magic)";
    return replay;
  }
  if (const auto version = get<std::uint32_t>(*blob, sizeof kJournalMagic); version != kVersion) {
    replay.problem = "unsupported journal version " + std::to_string(version);
    return replay;
  }
  std::lock_guard lock(mutex_);
  // A journal names the saved file it follows: one that follows another file holds pairs that file
  // already has. But with no pairs loaded (that file lost or set aside as corrupt) its pairs are in no
  // other place, and are kept.
  if (get<std::uint32_t>(*blob, sizeof kJournalMagic + 4) != saved_crc_ && !samples_.empty()) {
    replay.stale = true;
    return replay;
  }
  std::size_t at = kJournalHeaderSize;
  std::size_t first_skipped = 0;  // 1-based number of the first record skipped
  for (; at + kJournalRecordSize <= blob->size(); at += kJournalRecordSize) {
    const std::string_view record = std::string_view(*blob).substr(at, kRecordSize);
    if (get<std::uint32_t>(*blob, at + kRecordSize) != crc32(record)) break;
    const Sample s = get_record(*blob, at);
    // A whole record (its checksum holds) that is no pair: the records after it are sound, and kept.
    if (!plausible(s)) {
      if (replay.skipped++ == 0) first_skipped = (at - kJournalHeaderSize) / kJournalRecordSize + 1;
      continue;
    }
    push_back_locked(s);
    ++replay.recovered;
  }
  const std::size_t records = (at - kJournalHeaderSize) / kJournalRecordSize;
  if (replay.skipped > 0)
    replay.problem = std::to_string(replay.skipped) + " record(s) from record " +
                     std::to_string(first_skipped) +
                     " on hold their checksum but no plausible pair (skipped)";
  const auto also = [&](const std::string& text) {
    replay.problem += (replay.problem.empty() ? "" : "; ") + text;
  };
  if (at + kJournalRecordSize <= blob->size())
    also("record " + std::to_string(records + 1) + " fails its checksum; it and the " +
         std::to_string(blob->size() - at) + " bytes from it on are dropped");
  else if (at < blob->size())
    also(std::to_string(blob->size() - at) + " bytes at the end are not a whole record (dropped)");
  // The recovered pairs are in no saved file: they count as added since the save, and the journal is
  // rewritten with them (past any torn end) at the next append.
  new_samples_ += replay.recovered;
  since_save_ += replay.recovered;
  unjournaled_ = since_save_;
  journal_current_ = false;
  enforce_bounds_locked();
  return replay;
}

}  // namespace gearpulse::daemon
