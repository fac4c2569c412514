#include <catch2/catch.hpp>

#include <array>
#include <atomic>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <thread>
#include <vector>

#include "core/spsc_ring.hpp"

using gearpulse::SpscRing;

namespace {

#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
constexpr std::uint64_t kScale = 8;  // sanitizers are slow; the interleavings still get exercised
#else
constexpr std::uint64_t kScale = 1;
#endif

// Counts constructions and destructions and detects a destructor run twice on the same object or on
// storage that never held one.
struct Counted {
  static inline int live = 0;
  static inline int constructed = 0;
  static inline int destroyed = 0;
  static inline int bad_destroys = 0;
  static inline int throw_after = -1;  // copies left before a copy throws (-1: never)
  static constexpr std::uint32_t kAlive = 0xA11CEu;
  static constexpr std::uint32_t kDead = 0xDEADu;

  std::uint32_t magic = kAlive;
  int value = 0;

  explicit Counted(int v) : value(v) { note_construct(); }
  Counted(const Counted& o) : value(o.value) {
    if (throw_after == 0) throw std::runtime_error("copy failed");
    if (throw_after > 0) --throw_after;
    note_construct();
  }
  Counted(Counted&& o) noexcept : value(o.value) { note_construct(); }
  Counted& operator=(const Counted& o) = default;
  Counted& operator=(Counted&& o) noexcept {
    value = o.value;
    return *this;
  }
  ~Counted() {
    if (magic != kAlive) ++bad_destroys;
    magic = kDead;
    ++destroyed;
    --live;
  }
  static void note_construct() {
    ++constructed;
    ++live;
  }
  static void reset() { live = constructed = destroyed = bad_destroys = 0, throw_after = -1; }
};

}  // namespace

TEST_CASE("ring: capacity rounds up to a power of two and zero is rejected") {
  CHECK(SpscRing<int>(1).capacity() == 1);
  CHECK(SpscRing<int>(3).capacity() == 4);
  CHECK(SpscRing<int>(1000).capacity() == 1024);
  CHECK(SpscRing<int>(1024).capacity() == 1024);
  CHECK_THROWS_AS(SpscRing<int>(0), std::invalid_argument);
  CHECK_THROWS_AS(SpscRing<int>(~std::size_t{0}), std::length_error);
}

// The largest capacity a ring may have is an exact limit: one element more is refused as too large, not
// rounded up to an allocation of half the address space that fails with bad_alloc.
TEST_CASE("ring: a capacity one above the limit is too large") {
  constexpr std::size_t kMax = (std::size_t{1} << (8 * sizeof(std::size_t) - 2)) / sizeof(float);
  CHECK_THROWS_AS(SpscRing<float>(kMax + 1), std::length_error);
}

TEST_CASE("ring: capacity one holds exactly one element") {
  SpscRing<int> ring(1);
  CHECK(ring.try_push(7));
  CHECK_FALSE(ring.try_push(8));
  CHECK(ring.dropped() == 1);
  REQUIRE(ring.front() != nullptr);
  CHECK(*ring.front() == 7);
  ring.pop();
  CHECK(ring.front() == nullptr);
  CHECK(ring.try_push(9));
  std::array<int, 4> out{};
  CHECK(ring.read_bulk(out) == 1);
  CHECK(out[0] == 9);
  const std::array<int, 3> in{1, 2, 3};
  CHECK(ring.try_push_bulk(in) == 1);
  CHECK(ring.dropped() == 3);
}

TEST_CASE("ring: an empty ring yields nothing") {
  SpscRing<float> ring(5);
  CHECK(ring.empty());
  CHECK(ring.size() == 0);
  CHECK(ring.front() == nullptr);
  std::array<float, 8> out{};
  CHECK(ring.read_bulk(out) == 0);
  CHECK(ring.try_push_bulk(std::span<const float>{}) == 0);
  CHECK(ring.dropped() == 0);
  CHECK_FALSE(ring.take_overrun());
}

TEST_CASE("ring: a full ring drops and counts without blocking and reports the overrun once") {
  SpscRing<int> ring(6);  // 8 slots
  for (int i = 0; i < 8; ++i)
    REQUIRE(ring.try_push(i));
  CHECK(ring.size() == 8);
  CHECK_FALSE(ring.take_overrun());
  CHECK_FALSE(ring.try_push(100));
  CHECK_FALSE(ring.try_push(101));
  const std::array<int, 3> more{1, 2, 3};
  CHECK(ring.try_push_bulk(more) == 0);
  CHECK(ring.dropped() == 5);
  CHECK(ring.take_overrun());
  CHECK_FALSE(ring.take_overrun());
  // The contents are untouched by the drops.
  std::array<int, 8> out{};
  REQUIRE(ring.read_bulk(out) == 8);
  for (int i = 0; i < 8; ++i)
    CHECK(out[static_cast<std::size_t>(i)] == i);
}

// The tracker reads audio in blocks and stops at the first short one: a bulk read that took only what it
// saw at its previous look would leave frames written since then for a later turn, a backlog that grows.
TEST_CASE("ring: a bulk read takes everything written, also what came after the reader's last look") {
  SpscRing<int> ring(64);
  std::vector<int> in(10);
  std::iota(in.begin(), in.end(), 0);
  REQUIRE(ring.try_push_bulk(in) == 10);
  std::array<int, 4> small{};
  REQUIRE(ring.read_bulk(small) == 4);  // 6 left that the reader has seen
  std::iota(in.begin(), in.end(), 10);
  REQUIRE(ring.try_push_bulk(in) == 10);
  std::array<int, 32> out{};
  REQUIRE(ring.read_bulk(out) == 16);
  for (int i = 0; i < 16; ++i)
    CHECK(out[static_cast<std::size_t>(i)] == i + 4);
}

TEST_CASE("ring: bulk writes and reads wrap around at every offset and length") {
  for (std::size_t offset = 0; offset < 8; ++offset) {
    for (std::size_t len = 0; len <= 8; ++len) {
      SpscRing<int> ring(8);
      // Move the indices to `offset` first.
      for (std::size_t i = 0; i < offset; ++i) {
        REQUIRE(ring.try_push(-1));
        ring.pop();
      }
      std::vector<int> in(len + 3);
      std::iota(in.begin(), in.end(), 1);
      const std::size_t pushed = ring.try_push_bulk(in);
      CHECK(pushed == std::min<std::size_t>(len + 3, 8));
      CHECK(ring.dropped() == len + 3 - pushed);
      std::vector<int> out(len);
      const std::size_t got = ring.read_bulk(out);
      CHECK(got == std::min(len, pushed));
      for (std::size_t i = 0; i < got; ++i)
        CHECK(out[i] == static_cast<int>(i + 1));
      CHECK(ring.size() == pushed - got);
    }
  }
}

TEST_CASE("ring: every element is constructed and destroyed exactly once") {
  Counted::reset();
  {
    SpscRing<Counted> ring(4);
    REQUIRE(ring.try_emplace(1));
    REQUIRE(ring.try_push(Counted(2)));
    const Counted three(3);
    REQUIRE(ring.try_push(three));
    CHECK(ring.front()->value == 1);
    ring.pop();
    // Bulk push wraps (3 slots from index 3 on a 4-slot ring) and drops the tail.
    const std::vector<Counted> many{Counted(4), Counted(5), Counted(6), Counted(7)};
    CHECK(ring.try_push_bulk(many) == 2);
    std::vector<Counted> out{Counted(0), Counted(0)};
    REQUIRE(ring.read_bulk(out) == 2);
    CHECK(out[0].value == 2);
    CHECK(out[1].value == 3);
    // Two elements (4, 5) stay in the ring, wrapped, when it is destroyed.
    CHECK(ring.size() == 2);
  }
  CHECK(Counted::live == 0);
  CHECK(Counted::bad_destroys == 0);
  CHECK(Counted::constructed == Counted::destroyed);
}

TEST_CASE("ring: a throwing copy in a bulk push leaks nothing and publishes nothing") {
  Counted::reset();
  {
    SpscRing<Counted> ring(8);
    REQUIRE(ring.try_emplace(1));
    const std::vector<Counted> items{Counted(2), Counted(3), Counted(4)};
    Counted::throw_after = 2;
    CHECK_THROWS_AS(ring.try_push_bulk(items), std::runtime_error);
    Counted::throw_after = -1;
    CHECK(ring.size() == 1);
    CHECK(ring.try_push_bulk(items) == 3);
    CHECK(ring.size() == 4);
  }
  CHECK(Counted::live == 0);
  CHECK(Counted::bad_destroys == 0);
}

TEST_CASE("ring: two threads pass millions of single elements in order with the right checksum") {
  const std::uint64_t n = 4'000'000 / kScale;
  SpscRing<std::uint64_t> ring(1000);
  std::uint64_t sum = 0, expected_next = 0, out_of_order = 0;
  std::thread consumer([&] {
    while (expected_next < n) {
      const std::uint64_t* v = ring.front();
      if (!v) {
        std::this_thread::yield();
        continue;
      }
      if (*v != expected_next) ++out_of_order;
      sum += *v;
      ++expected_next;
      ring.pop();
    }
  });
  std::uint64_t retries = 0;
  for (std::uint64_t i = 0; i < n; ++i) {
    // try_push never waits; this test's producer retries, a capture thread would drop.
    while (!ring.try_push(i)) {
      ++retries;
      std::this_thread::yield();
    }
  }
  consumer.join();
  CHECK(out_of_order == 0);
  CHECK(sum == n * (n - 1) / 2);
  CHECK(ring.dropped() == retries);
  CHECK(ring.empty());
}

TEST_CASE("ring: two threads with bulk transfers and drops keep order and account for every element") {
  const std::uint64_t n = 8'000'000 / kScale;
  SpscRing<std::uint64_t> ring(4096);
  std::atomic<bool> done{false};
  std::uint64_t received = 0, received_sum = 0, last = 0, disorder = 0;
  std::thread consumer([&] {
    std::vector<std::uint64_t> buf(777);  // not a divisor of the capacity: reads wrap at all offsets
    bool first = true;
    for (;;) {
      const bool finished = done.load(std::memory_order_acquire);
      const std::size_t got = ring.read_bulk(buf);
      for (std::size_t i = 0; i < got; ++i) {
        if (!first && buf[i] <= last) ++disorder;
        first = false;
        last = buf[i];
        received_sum += buf[i];
      }
      received += got;
      if (got == 0) {
        if (finished) break;
        std::this_thread::yield();
      }
    }
  });
  std::vector<std::uint64_t> block(1000);
  std::uint64_t next = 0, dropped = 0, dropped_sum = 0;
  while (next < n) {
    const std::size_t len =
        static_cast<std::size_t>(std::min<std::uint64_t>(block.size() - next % 7, n - next));
    for (std::size_t i = 0; i < len; ++i)
      block[i] = next + i;
    const std::size_t pushed = ring.try_push_bulk(std::span<const std::uint64_t>(block.data(), len));
    for (std::size_t i = pushed; i < len; ++i)
      dropped_sum += block[i];
    dropped += len - pushed;
    next += len;
  }
  done.store(true, std::memory_order_release);
  consumer.join();
  CHECK(disorder == 0);
  CHECK(ring.dropped() == dropped);
  CHECK(received + dropped == n);
  CHECK(received_sum + dropped_sum == n * (n - 1) / 2);
  INFO("dropped " << dropped << " of " << n);
  CHECK(received > 0);
}
