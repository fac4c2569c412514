#include <catch2/catch.hpp>

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
