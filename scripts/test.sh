#!/usr/bin/env bash
# The one test command: installs what is missing, builds with warnings as errors, runs every test,
# then again under AddressSanitizer+UndefinedBehaviorSanitizer, the threaded parts (the ring, capture,
# gpsd client, pulse thread, log queue, control server, persistence, the in-process pipeline and the
# daemon's process) under ThreadSanitizer, and checks formatting. Exit status is non-zero if anything fails,
# and if a test skipped that must run here: every test that needs the real logs (../shared/data/real) or a
# program setup.sh installs runs; only the skips listed in may_skip below are allowed (docs/testing.md).
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc 2>/dev/null || echo 2)
logs=$(mktemp -d)
trap 'rm -rf "$logs"' EXIT

bash scripts/setup.sh

# Tests that may skip on this machine (ctest names, an extended regex): the GPIO tests without a GPIO chip,
# and the tests that need root when not run as root (locked memory, a tmpfs mounted, a gearpulsed that user
# nobody may run).
may_skip='^$'
if ! compgen -G '/dev/gpiochip*' >/dev/null; then may_skip+='|^gpio: '; fi
if [ "$(id -u)" -ne 0 ]; then
  may_skip+='|^realtime: locked memory|^daemon: a state_dir without room|^daemon: a state directory it may not'
fi
# Under the sanitizers: locking memory (their shadow mappings make it meaningless) and running out of file
# descriptors (AddressSanitizer's runtime needs them).
may_skip_sanitized="$may_skip|^realtime: locked memory|^control: out of file descriptors"

# Fails unless every test ctest reported skipped in log $1 matches the extended regex $2.
require_ran() {
  local bad
  bad=$(sed -n 's/^[[:space:]]*[0-9]* - \(.*\) (Skipped)$/\1/p' "$1" | grep -Ev "$2" || true)
  if [ -n "$bad" ]; then
    printf '== FAILED: these tests skipped and must run here:\n%s\n' "$bad" >&2
    exit 1
  fi
}

echo "== format check"
git ls-files '*.cpp' '*.hpp' | xargs -r clang-format --dry-run --Werror

echo "== release build + tests"
cmake -S . -B build -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j"$jobs"
ctest --test-dir build --output-on-failure -j"$jobs" | tee "$logs/release.log"
require_ran "$logs/release.log" "$may_skip"

echo "== ASan+UBSan build + tests"
# The benchmarks are built (with -Werror) above and not run here: the sanitizer build skips them. -O1 and
# line tables only (-g1, enough for the sanitizers' file:line reports) build it in about 6 minutes on 2
# cores instead of about 11 with -O2 -g.
cmake -S . -B build-asan -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" \
  -DGEARPULSE_SANITIZE=address,undefined -DGEARPULSE_BENCH=OFF >/dev/null
cmake --build build-asan -j"$jobs"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --test-dir build-asan --output-on-failure -j"$jobs" | tee "$logs/asan.log"
require_ran "$logs/asan.log" "$may_skip_sanitized"

echo "== TSan: the threaded parts"
# Every test of these files (ctest lists only the cases of the executables built, so the names' prefixes
# select exactly them): about 2 minutes to build and 1.5 to run on 2 cores, -O1 as the ASan build.
cmake -S . -B build-tsan -DGEARPULSE_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DGEARPULSE_SANITIZE=thread -DGEARPULSE_BENCH=OFF >/dev/null
cmake --build build-tsan -j"$jobs" --target spsc_ring_test alsa_capture_test gpsd_client_test pulse_thread_test \
  log_queue_test control_test persistence_test pipeline_test gearpulsed gearpulsectl daemon_run_test
TSAN_OPTIONS=halt_on_error=1 ctest --test-dir build-tsan --output-on-failure -j"$jobs" \
  -R "^(ring|alsa|gpsd|pulse|log queue|control|daemon|pipeline):" | tee "$logs/tsan.log"
require_ran "$logs/tsan.log" "$may_skip_sanitized"
echo "== all tests passed"
