#pragma once
// The control socket protocol, shared by gearpulsed and gearpulsectl (header only).
// JSON lines over a Unix stream socket: one request object per line, one reply object per line.
//   request: {"v":1,"cmd":"status"}            (also "gears", "retrain", "reset-model" with "confirm":true)
//   reply:   {"v":1,"ok":true,...}  or  {"v":1,"ok":false,"error":"<one line>"}
// "v" may be omitted in a request (taken as the current version); a newer version is refused.
#include <cstddef>

namespace gearpulse::control {

inline constexpr int kProtocolVersion = 1;
// A request line longer than this is refused with an error reply and the connection is closed.
inline constexpr std::size_t kMaxRequestBytes = 4096;

}  // namespace gearpulse::control
