#include <catch2/catch.hpp>

#include <cstdint>
#include <string>

#include "daemon/pipeline_state.hpp"

using namespace gearpulse::daemon;

namespace {

template <class E, class Table>
void check_round_trip(const Table& table) {
  for (const auto& [value, name] : table) {
    INFO(std::string(name));
    CHECK(to_string(value) == name);
    CHECK(state_from_string<E>(name) == value);
  }
  CHECK_FALSE(state_from_string<E>("").has_value());
  CHECK_FALSE(state_from_string<E>("Running").has_value());
}

}  // namespace

TEST_CASE("pipeline: each state has the word status gives it, and the word reads back") {
  check_round_trip<OutputState>(state_names::kOutput);
  check_round_trip<GpsState>(state_names::kGps);
  check_round_trip<AudioState>(state_names::kAudio);
  // The words of docs/interfaces.md.
  for (const char* word : {"ok", "off", "error", "write-errors", "reader-behind", "no-reader"})
    CHECK(state_from_string<OutputState>(word).has_value());
  for (const char* word : {"disconnected", "no-fix", "fix"})
    CHECK(state_from_string<GpsState>(word).has_value());
  for (const char* word : {"running", "recovering", "frozen", "stalled", "retrying"})
    CHECK(state_from_string<AudioState>(word).has_value());
  CHECK(to_string(GpsState::kNoFix) == "no-fix");
  CHECK(to_string(OutputState::kReaderBehind) == "reader-behind");
}

TEST_CASE("pipeline: a fault count is current while it grew within the time, then not") {
  RecentGrowth writes;
  constexpr std::int64_t kWithin = 5'000'000'000;                // 5 s
  CHECK_FALSE(writes.grew_recently(0, 1'000'000'000, kWithin));  // nothing failed yet
  CHECK(writes.grew_recently(3, 2'000'000'000, kWithin));        // three writes failed
  CHECK(writes.grew_recently(3, 6'900'000'000, kWithin));        // 4.9 s later, none since
  CHECK_FALSE(writes.grew_recently(3, 7'000'000'000, kWithin));  // 5 s without a new failure: over
  CHECK(writes.grew_recently(4, 8'000'000'000, kWithin));        // one more: current again
}
