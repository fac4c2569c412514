#pragma once
// The newest value one thread publishes and any thread reads, without a lock on either side: a real-time
// reader never waits for the writer (no priority inversion), and the writer never waits for a reader.
// Two slots, each a seqlock, and the index of the one written last: the writer fills the slot not
// published, then publishes it, so a writer stopped half-way through a write (preempted, or held up by
// a lower priority than the reader's) leaves the published slot whole. A read is retried only when the
// writer has meanwhile published (the count changed, or the slot being read is being written again), that
// is, only when the writer made progress; at the rates a GPS fix comes, practically never. Reads of one
// thread never go back in time: a read returns the value of the publish count it saw, no later one.
// The slots hold the value as words of std::atomic (no fences, no data race on a torn copy), so
// ThreadSanitizer checks it as it is: the writer's release stores of the words keep the odd sequence
// number before them, the reader's acquire loads of them keep its second look at the sequence after them.
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace gearpulse {

template <typename T>
class Published {
  static_assert(std::is_trivially_copyable_v<T> && std::is_default_constructible_v<T>);

 public:
  explicit Published(const T& initial = T{}) noexcept { write(slots_[0], initial); }
  Published(const Published&) = delete;
  Published& operator=(const Published&) = delete;

  // One writer thread at a time.
  void publish(const T& value) noexcept {
    const std::uint64_t n = published_.load(std::memory_order_relaxed);
    write(slots_[(n + 1) % 2], value);
    published_.store(n + 1, std::memory_order_release);
  }

  // Any thread: the value of the last publish() that has returned (or a later one).
  [[nodiscard]] T read() const noexcept {
    Words words{};
    for (;;) {
      const std::uint64_t p = published_.load(std::memory_order_acquire);
      const Slot& slot = slots_[p % 2];
      const std::uint64_t s1 = slot.seq.load(std::memory_order_acquire);
      for (std::size_t i = 0; i < kWords; ++i)
        words[i] = slot.words[i].load(std::memory_order_acquire);
      const std::uint64_t s2 = slot.seq.load(std::memory_order_relaxed);
      // Still the slot published as p: a reader held up between its look at published_ and the words could
      // otherwise read, whole, the slot of publish p + 2 before published_ says so, and its next read the
      // older p + 1 (a value going back in time).
      if (s1 == s2 && (s1 & 1u) == 0 && published_.load(std::memory_order_relaxed) == p) break;
    }
    T value;
    std::memcpy(static_cast<void*>(&value), words.data(), sizeof(T));  // T is trivially copyable
    return value;
  }

 private:
  static constexpr std::size_t kWords = (sizeof(T) + sizeof(std::uint64_t) - 1) / sizeof(std::uint64_t);
  using Words = std::array<std::uint64_t, kWords>;
  struct Slot {
    std::atomic<std::uint64_t> seq{0};  // odd while the writer is writing the words
    std::array<std::atomic<std::uint64_t>, kWords> words{};
  };

  static void write(Slot& slot, const T& value) noexcept {
    Words words{};
    std::memcpy(words.data(), &value, sizeof(T));
    const std::uint64_t seq = slot.seq.load(std::memory_order_relaxed);
    slot.seq.store(seq + 1, std::memory_order_relaxed);
    for (std::size_t i = 0; i < kWords; ++i)
      slot.words[i].store(words[i], std::memory_order_release);
    slot.seq.store(seq + 2, std::memory_order_release);
  }

  std::array<Slot, 2> slots_;
  std::atomic<std::uint64_t> published_{0};  // how many publish() calls: the slot read is this % 2
};

}  // namespace gearpulse
