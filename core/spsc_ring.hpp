#pragma once
// Lock-free single-producer/single-consumer ring (audio frames from the capture thread to the tracker).
// Free-running 64-bit indices on their own cache lines; each side caches the other's index so the
// common case touches no shared line; acquire/release only. The producer never spins: a push that does
// not fit is dropped and counted, and the consumer can see that an overrun happened.
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <new>
#include <span>
#include <stdexcept>
#include <type_traits>
#include <utility>

namespace gearpulse {

inline constexpr std::size_t kCacheLine = 64;

template <typename T>
class SpscRing {
  static_assert(std::is_nothrow_destructible_v<T>);

 public:
  // Capacity is rounded up to a power of two; allocation happens here and nowhere else.
  explicit SpscRing(std::size_t min_capacity)
      : capacity_(checked_capacity(min_capacity)), mask_(capacity_ - 1) {
    storage_ = std::make_unique<Slot[]>(capacity_);
  }
  ~SpscRing() {
    const std::uint64_t w = write_.load(std::memory_order_acquire);
    for (std::uint64_t r = read_.load(std::memory_order_relaxed); r != w; ++r)
      slot(r)->~T();
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  // ---- producer side ----
  template <typename... Args>
  bool try_emplace(Args&&... args) noexcept(std::is_nothrow_constructible_v<T, Args&&...>) {
    const std::uint64_t w = write_.load(std::memory_order_relaxed);
    if (w - read_cache_ >= capacity_) {
      read_cache_ = read_.load(std::memory_order_acquire);
      if (w - read_cache_ >= capacity_) {
        note_drop(1);
        return false;
      }
    }
    ::new (static_cast<void*>(slot(w))) T(std::forward<Args>(args)...);
    write_.store(w + 1, std::memory_order_release);
    return true;
  }
  bool try_push(const T& value) noexcept(std::is_nothrow_copy_constructible_v<T>) {
    return try_emplace(value);
  }
  bool try_push(T&& value) noexcept(std::is_nothrow_move_constructible_v<T>) {
    return try_emplace(std::move(value));
  }

  // Writes as many leading elements of `items` as fit (with wrap-around), counts the rest as dropped.
  // If a copy throws, the elements of this call already built are destroyed and nothing is published.
  std::size_t try_push_bulk(std::span<const T> items) noexcept(std::is_nothrow_copy_constructible_v<T>) {
    const std::uint64_t w = write_.load(std::memory_order_relaxed);
    std::size_t free_slots = capacity_ - static_cast<std::size_t>(w - read_cache_);
    if (free_slots < items.size()) {
      read_cache_ = read_.load(std::memory_order_acquire);
      free_slots = capacity_ - static_cast<std::size_t>(w - read_cache_);
    }
    const std::size_t n = std::min(free_slots, items.size());
    if constexpr (std::is_trivially_copyable_v<T>) {
      const std::size_t first = std::min(n, capacity_ - static_cast<std::size_t>(w & mask_));
      if (first) std::memcpy(static_cast<void*>(slot(w)), items.data(), first * sizeof(T));
      if (n > first)
        std::memcpy(static_cast<void*>(slot(w + first)), items.data() + first, (n - first) * sizeof(T));
    } else {
      std::size_t built = 0;
      try {
        for (; built < n; ++built)
          ::new (static_cast<void*>(slot(w + built))) T(items[built]);
      } catch (...) {
        while (built > 0)
          slot(w + --built)->~T();
        throw;
      }
    }
    write_.store(w + n, std::memory_order_release);
    if (n < items.size()) note_drop(items.size() - n);
    return n;
  }

  // ---- consumer side ----
  // Pointer to the oldest element, or nullptr when empty. Valid until pop(). pop() requires a non-null
  // front() before it (it does not check, to stay branch-free on the consumer's fast path).
  [[nodiscard]] T* front() noexcept {
    const std::uint64_t r = read_.load(std::memory_order_relaxed);
    if (r == write_cache_) {
      write_cache_ = write_.load(std::memory_order_acquire);
      if (r == write_cache_) return nullptr;
    }
    return slot(r);
  }
  void pop() noexcept {
    const std::uint64_t r = read_.load(std::memory_order_relaxed);
    slot(r)->~T();
    read_.store(r + 1, std::memory_order_release);
  }
  // Moves up to out.size() oldest elements into `out` (with wrap-around); returns how many.
  std::size_t read_bulk(std::span<T> out) noexcept requires std::is_nothrow_move_assignable_v<T> {
    const std::uint64_t r = read_.load(std::memory_order_relaxed);
    std::size_t available = static_cast<std::size_t>(write_cache_ - r);
    if (available < out.size()) {
      write_cache_ = write_.load(std::memory_order_acquire);
      available = static_cast<std::size_t>(write_cache_ - r);
    }
    const std::size_t n = std::min(available, out.size());
    const std::size_t first = std::min(n, capacity_ - static_cast<std::size_t>(r & mask_));
    move_out(out.data(), slot(r), first);
    move_out(out.data() + first, slot(r + first), n - first);
    read_.store(r + n, std::memory_order_release);
    return n;
  }

  // ---- either side ----
  [[nodiscard]] std::size_t capacity() const noexcept { return capacity_; }
  // Approximate fill level (exact when called from one side while the other is idle). The read index
  // is loaded first: it can only run up to the write index, so a later write load is never behind it.
  [[nodiscard]] std::size_t size() const noexcept {
    const std::uint64_t r = read_.load(std::memory_order_acquire);
    const std::uint64_t w = write_.load(std::memory_order_acquire);
    return static_cast<std::size_t>(w - r);
  }
  [[nodiscard]] bool empty() const noexcept { return size() == 0; }
  // Elements the producer could not push since construction.
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_.load(std::memory_order_relaxed); }
  // True once if an overrun happened since the last call (consumer side: the stream has a hole).
  [[nodiscard]] bool take_overrun() noexcept { return overrun_.exchange(false, std::memory_order_acq_rel); }

 private:
  struct alignas(alignof(T)) Slot {
    std::byte bytes[sizeof(T)];
  };

  static std::size_t checked_capacity(std::size_t n) {
    if (n == 0) throw std::invalid_argument("SpscRing: capacity must be positive");
    constexpr std::size_t kMax = (std::size_t{1} << (8 * sizeof(std::size_t) - 2)) / sizeof(T);
    if (n > kMax) throw std::length_error("SpscRing: capacity too large");
    std::size_t p = 1;
    while (p < n)
      p <<= 1;
    return p;
  }
  T* slot(std::uint64_t index) noexcept {
    return std::launder(reinterpret_cast<T*>(storage_[static_cast<std::size_t>(index & mask_)].bytes));
  }
  static void move_out(T* dst, T* src, std::size_t n) noexcept {
    if constexpr (std::is_trivially_copyable_v<T>) {
      if (n) std::memcpy(static_cast<void*>(dst), src, n * sizeof(T));
    } else {
      for (std::size_t i = 0; i < n; ++i) {
        dst[i] = std::move(src[i]);
        src[i].~T();
      }
    }
  }
  void note_drop(std::size_t n) noexcept {
    dropped_.fetch_add(n, std::memory_order_relaxed);
    overrun_.store(true, std::memory_order_release);
  }

  const std::size_t capacity_;
  const std::size_t mask_;
  std::unique_ptr<Slot[]> storage_;

  alignas(kCacheLine) std::atomic<std::uint64_t> write_{0};
  std::uint64_t read_cache_ = 0;  // producer's copy of read_
  alignas(kCacheLine) std::atomic<std::uint64_t> read_{0};
  std::uint64_t write_cache_ = 0;  // consumer's copy of write_
  alignas(kCacheLine) std::atomic<std::uint64_t> dropped_{0};
  std::atomic<bool> overrun_{false};
};

}  // namespace gearpulse
